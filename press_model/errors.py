"""Errors a user can act on.

Every error the toolkit raises for bad input derives from :class:`ServoPressError`; the command line
prints its message and exits non-zero without a traceback.
"""


class ServoPressError(Exception):
    """Base class: a problem with the user's input or request, with a message that says how to fix it."""


class PressDataError(ServoPressError):
    """A field of a press, job or parameter file is missing or out of range."""

    def __init__(self, source: str, field: str, value, expected: str):
        self.source, self.field, self.value, self.expected = source, field, value, expected
        super().__init__(f"{source}: {field} = {value!r} is not valid: {expected}")


class AssemblyError(ServoPressError):
    """The linkage cannot be assembled (or leaves its branch) at some crank angle."""


class SolverError(ServoPressError):
    """A numerical solve did not converge; the message names where and why."""
