"""A helper process forked at a command's start, to do its imports and later work beside the command's own, and
independent steps of a command run side by side.

On two cores a command's heavy imports (SALib with scipy.stats and pandas, matplotlib) and the work that
needs them can run on the other core while the command loads the press and computes; the command itself
then never imports them. :func:`beside` runs a whole step (a function) in a process forked for it and hands
its result back.
"""
from __future__ import annotations

import ctypes
import multiprocessing
import os
import pickle
import signal
import sys
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from .errors import ServoPressError


@contextmanager
def warm_process(warm: Callable[[], None]) -> Iterator[ProcessPoolExecutor | None]:
    """One process, forked now, that runs ``warm()`` (its imports) at once and then the tasks it is given.

    Yields the pool, or None where the system cannot fork (the caller then does the work itself). Ctrl-C
    reaches the whole process group: the helper ignores it, and the command stops it without a traceback. The
    helper ends with the command, also when the command is killed (:func:`die_with_parent`).
    """
    if "fork" not in multiprocessing.get_all_start_methods():
        yield None
        return
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"), initializer=_start,
                             initargs=(warm, os.getpid())) as pool:
        pool.submit(int)  # the pool forks its process at the first task: now, not when the work is wanted
        yield pool


SECOND_PROCESS = " (second process)"  # marks a step or phase run in a process beside the command's own (progress, timings)
_PR_SET_PDEATHSIG = 1  # prctl(2) option, <linux/prctl.h>


def die_with_parent(parent: int) -> None:
    """In a process just forked from ``parent`` (its pid): end this process by SIGTERM when its parent ends, however
    it ends (SIGKILL included), so that no helper is left running alone (Linux; elsewhere only the check below).

    SIGTERM gets its default action back (the command's handler, inherited by the fork, would raise in here). The
    parent may have died before the request took effect: then the parent is already not ``parent``, and this
    process ends at once."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - a libc without prctl
            pass
    if os.getppid() != parent:
        os._exit(128 + signal.SIGTERM)


def _start(warm: Callable[[], None], parent: int) -> None:
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warm()


class Beside:
    """Work running in a process forked for it, beside the caller's own (see :func:`beside`)."""

    def __init__(self, work: Callable[[], object]):
        self._work = work
        self._message = None
        self._process = self._conn = None
        if "fork" in multiprocessing.get_all_start_methods():
            for stream in (sys.stdout, sys.stderr):  # what sits in a buffer now would be written again by the child
                stream.flush()
            ctx = multiprocessing.get_context("fork")
            self._conn, child_end = ctx.Pipe(duplex=False)
            # not a daemon: the work may fork processes of its own (the Sobol analysis does); stop() ends it instead
            self._process = ctx.Process(target=_run_beside, args=(child_end, work, os.getpid()))
            self._process.start()
            child_end.close()

    def failed(self) -> bool:
        """True once the work has ended with an error (without waiting for it)."""
        if self._process is not None and self._message is None and self._conn.poll():
            self._receive()
        return self._message is not None and self._message[0] != "ok"

    @property
    def forked(self) -> bool:
        """True when the work runs in its own process (False where the system cannot fork)."""
        return self._process is not None

    def running(self) -> bool:
        """True while the process still works (False where the system cannot fork: the work waits for result())."""
        return self._process is not None and self._message is None and self._process.is_alive() and not self._conn.poll()

    def result(self):
        """Wait for the work and return what it returned; raise what it raised (an error that cannot cross between
        processes as a :class:`ServoPressError` with its message, or a RuntimeError with its traceback). Where the
        system cannot fork, runs the work now."""
        if self._process is None:
            return self._work()
        if self._message is None:
            self._receive()
        kind, value = self._message
        if kind == "ok":
            return value
        if kind == "error":
            raise value
        if kind == "user-error":
            raise ServoPressError(value)
        raise RuntimeError(value)

    def _receive(self) -> None:
        try:
            self._message = self._conn.recv()
        except EOFError:
            self._process.join()
            self._message = ("crash", f"the second process ended without a result (exit code {self._process.exitcode})")
        self._process.join()

    def stop(self) -> None:
        """End the process if it still runs (the caller gave up on the work)."""
        if self._process is not None and self._process.is_alive():
            self._process.terminate()
            self._process.join()


@contextmanager
def beside(work: Callable[[], object]) -> Iterator[Beside]:
    """``work()`` in a process forked now, while the caller goes on; ``.result()`` waits for it. On two cores this runs
    independent steps of a command side by side. Leaving the block without the result (an error, Ctrl-C) ends the
    process; Ctrl-C reaches the whole process group, the process ignores it. Where the system cannot fork, ``.result()``
    does the work in the caller."""
    b = Beside(work)
    try:
        yield b
    finally:
        b.stop()


def _run_beside(conn, work: Callable[[], object], parent: int) -> None:
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        message = ("ok", work())
    except ServoPressError as exc:
        message = ("error", exc)
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception:  # e.g. an error class whose __init__ takes other arguments than its message
            message = ("user-error", str(exc))
    except BaseException:  # noqa: BLE001 (handed to the caller, which raises it)
        message = ("crash", traceback.format_exc())
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    try:
        conn.send(message)
    except Exception:  # noqa: BLE001 (a result that cannot be pickled: say so rather than end without a word)
        conn.send(("crash", traceback.format_exc()))
    conn.close()
