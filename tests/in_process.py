"""`servo-press` run inside the test's own process (tests/ is on sys.path, conftest.py): for tests that need a
command's outputs, exit code and printed lines but nothing of the process itself. Each subprocess of
``python -m servo_press.cli`` imports Pinocchio, CasADi, numba and matplotlib again (seconds a launch); the tests
where the process is what is checked (signals, exit codes 130/143, locks, forked workers, a fresh import, the
installed script) keep their subprocesses."""
from __future__ import annotations

import contextlib
import io
import subprocess
from pathlib import Path

from servo_press.cli import main


def servo_press(*argv, cwd: Path | str | None = None) -> subprocess.CompletedProcess:
    """``servo-press argv`` through :func:`servo_press.cli.main` in this process, in the folder ``cwd`` (this one if
    None); returns what ``subprocess.run(..., capture_output=True, text=True)`` would: returncode, stdout, stderr.
    An exception main() does not turn into an exit code (a traceback in a real process) is raised to the test."""
    args = [str(a) for a in argv]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.ExitStack() as stack:
        if cwd is not None:
            stack.enter_context(contextlib.chdir(cwd))
        stack.enter_context(contextlib.redirect_stdout(out))
        stack.enter_context(contextlib.redirect_stderr(err))
        try:
            code = main(args)
        except SystemExit as exc:  # argparse refuses with its usage and exit 2, --version exits 0
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return subprocess.CompletedProcess(["servo-press", *args], code, out.getvalue(), err.getvalue())
