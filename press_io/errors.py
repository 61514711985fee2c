"""Errors a user can act on.

Every error the toolkit raises for bad input derives from :class:`ServoPressError`; the command line
prints its message and exits non-zero without a traceback.
"""


class ServoPressError(Exception):
    """Base class: a problem with the user's input or request, with a message that says how to fix it."""


def one_line(text) -> str:
    """``text`` with every unprintable character (line breaks, tabs, controls) written as its escape, so that a
    message quoting a user's key or file name stays on one line."""
    s = str(text)
    return s if s.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in s)


class PressDataError(ServoPressError):
    """A field of a press, job or parameter file is missing or out of range."""

    def __init__(self, source: str, field: str, value, expected: str):
        self.source, self.field, self.value, self.expected = source, field, value, expected
        # source and field can hold a user's file name or key: escaped so the message stays one line
        super().__init__(f"{one_line(source)}: {one_line(field)} = {value!r} is not valid: {one_line(expected)}")


def os_error(exc: OSError) -> ServoPressError:
    """The one-line error for a path the system refuses (an output folder that is a file or lies under one,
    a folder where a file is wanted, a name too long, no permission), naming the user's path."""
    path = exc.filename2 if exc.filename2 is not None else exc.filename  # os.replace: the target, not the temp file
    reason = exc.strerror or exc.__class__.__name__
    return ServoPressError(f"{one_line(path if path is not None else '<path>')}: {one_line(reason)}: check this path "
                           "(an output folder must not be an existing file nor lie under one; an output file must not be a folder)")


class AssemblyError(ServoPressError):
    """The linkage cannot be assembled (or leaves its branch) at some crank angle."""


class SolverError(ServoPressError):
    """A numerical solve did not converge; the message names where and why."""


class PlanningError(ServoPressError):
    """No admissible stroke exists (or the solver failed); the message names where, which limit and the fix."""
