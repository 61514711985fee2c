"""The planner's error: a job that cannot be planned, with the crank angle, the limit and the fix."""
from press_io.errors import ServoPressError


class PlanningError(ServoPressError):
    """No admissible stroke exists (or the solver failed); the message names where, which limit and the fix."""
