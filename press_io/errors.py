"""Errors a user can act on.

Every error the toolkit raises for bad input derives from :class:`ServoPressError`; the command line
prints its message and exits non-zero without a traceback.
"""
import errno


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


_FULL = "the disk (or the quota) that holds it is full: free some space there, or choose an --out on another disk"
_DENIED = "you may not write there (no permission, or a read-only file system): choose an --out in a folder you can write"
_HINTS = {errno.ENOSPC: _FULL, errno.EDQUOT: _FULL, errno.EACCES: _DENIED, errno.EPERM: _DENIED, errno.EROFS: _DENIED,
          errno.ENAMETOOLONG: "a name in this path is longer than the file system allows: choose a shorter --out",
          errno.ENOTDIR: "a folder in this path is an existing file: an output folder must not be an existing file nor lie under one",
          errno.EEXIST: "an output folder must not be an existing file nor lie under one",
          errno.EISDIR: "it is a folder where an output file is wanted: choose a file path"}


def os_error(exc: OSError) -> ServoPressError:
    """The one-line error for a path the system refuses, naming the user's path (the output the write was for when
    the system names none) and what to do about the system's reason: a full disk, no permission or a read-only file
    system, a name too long, a file where a folder is wanted or the other way round."""
    path = exc.filename2 if exc.filename2 is not None else exc.filename  # os.replace: the target, not the temp file
    reason = exc.strerror or exc.__class__.__name__
    hint = _HINTS.get(exc.errno, "check this path (an output folder must not be an existing file nor lie under one; an "
                                 "output file must not be a folder)")
    where = one_line(path) if path is not None else "writing the output"
    return ServoPressError(f"{where}: {one_line(reason)}: {hint}")


class AssemblyError(ServoPressError):
    """The linkage cannot be assembled (or leaves its branch) at some crank angle."""


class SolverError(ServoPressError):
    """A numerical solve did not converge; the message names where and why."""


class PlanningError(ServoPressError):
    """No admissible stroke exists (or the solver failed); the message names where, which limit and the fix."""
