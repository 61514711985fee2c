"""Ctrl-C (SIGINT) and SIGTERM: a run stops by one exception, whatever it was doing, and never half-swaps a result.

The command line turns both signals into :class:`Interrupted` (a ``KeyboardInterrupt``, so that every ``finally``
and ``with`` on the way out runs and removes what the run had started); it exits ``128 + signal``: 130 for
Ctrl-C, 143 for SIGTERM. :func:`deferred` holds the signals over a step that must not be cut in two (the swap
of a result folder, a cluster's close), :func:`watch` notices a signal that a library caught and swallowed
(CasADi turns Ctrl-C inside IPOPT into a solver status).
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """The run was stopped by the signal ``signum`` (SIGINT: Ctrl-C, SIGTERM: a service manager or ``kill``)."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        """The shell's status of a process ended by the signal: 128 + its number (130 SIGINT, 143 SIGTERM)."""
        return 128 + self.signum


def exit_status(exc: KeyboardInterrupt) -> int:
    """The exit status for ``exc``: its signal's (:attr:`Interrupted.exit_status`), 130 for a plain KeyboardInterrupt."""
    return exc.exit_status if isinstance(exc, Interrupted) else 128 + signal.SIGINT


def _raise(signum, frame) -> None:
    raise Interrupted(signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()  # only the main thread may set a signal's handler


@contextmanager
def handled() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` while the block runs (the handlers before it are restored at
    its end). Outside the main thread: nothing changes."""
    if not _main_thread():
        yield
        return
    old = {s: signal.signal(s, _raise) for s in SIGNALS}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _hooked(handler) -> dict:
    """Install ``handler`` for the signals whose handler is Python code now; returns the ones replaced. An ignored
    signal stays ignored and a default one keeps ending the process (SIGTERM outside the command line)."""
    old = {s: signal.getsignal(s) for s in SIGNALS}
    hooked = {s: h for s, h in old.items() if callable(h)}
    for s in hooked:
        signal.signal(s, handler)
    return hooked


@contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while the block runs, so that it is never cut short; a signal received meanwhile is
    raised as :class:`Interrupted` when the block ends (chained to the block's own error, if it raised one)."""
    if not _main_thread():
        yield
        return
    got: list[int] = []
    hooked = _hooked(lambda signum, frame: got.append(signum))
    try:
        yield
    except BaseException as exc:
        if got and not isinstance(exc, KeyboardInterrupt):
            raise Interrupted(got[0]) from exc
        raise
    finally:
        for s, h in hooked.items():
            signal.signal(s, h)
    if got:
        raise Interrupted(got[0])


@dataclass
class Seen:
    """What :func:`watch` saw: the first signal received in its block, or None."""

    signum: int | None = None


@contextmanager
def watch() -> Iterator[Seen]:
    """Around a call into a library that catches Python's exceptions: SIGINT and SIGTERM raise :class:`Interrupted`
    as usual (the library stops at its next check), and the block's :class:`Seen` records the signal, so that the
    caller can raise it again when the library swallowed it and returned as if it had finished or failed."""
    seen = Seen()
    if not _main_thread():
        yield seen
        return

    def note(signum, frame):
        if seen.signum is None:
            seen.signum = signum
        raise Interrupted(signum)

    hooked = _hooked(note)
    try:
        yield seen
    finally:
        for s, h in hooked.items():
            signal.signal(s, h)
