"""Ctrl-C in `servo-press monitor` on local worker processes, and what its --help says it runs.

The terminal sends SIGINT to the whole foreground process group: the command and the Dask worker processes
under it. The workers used to die of it under their nannies and log tracebacks before the command's
"servo-press: interrupted"; now they ignore it (calibration.fleet.cluster.local_cluster) and the command closes the
cluster in order. A subprocess in its own session plays the terminal here.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from servo_press.cli import build_parser, main


def test_monitor_help_names_the_method_that_runs():
    text = " ".join(build_parser()._subparsers._group_actions[0].choices["monitor"].format_help().split())
    assert "differential-evolution)" not in text and "aco, the ant colony, in the shipped jobs" in text
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job

    assert CalibrationSettings.from_job(load_job("cushion-test")).default_method == "aco"


def test_ctrl_c_during_a_local_monitor_run_prints_one_line(tmp_path):
    """On the cheap test job of test_monitor.py (two strokes a log, one least-squares start): what is checked is the
    interrupt of a busy cluster, which any job's calibrations give, not their results."""
    job = str(Path(__file__).resolve().parent / "data" / "cushion_test_fast.toml")
    assert main(["experiment", "--job", job, "--fleet", "3", "--out", str(tmp_path / "fleet")]) == 0
    exe = shutil.which("servo-press")
    cmd = [exe] if exe else [sys.executable, "-m", "servo_press.cli"]
    proc = subprocess.Popen([*cmd, "monitor", "--logs", str(tmp_path / "fleet"), "--job", job, "--workers", "2",
                             "--out", str(tmp_path / "mon")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as a terminal's job has it
    seen = []
    try:
        for line in proc.stderr:  # wait until the workers have finished one log: the cluster is up and busy
            seen.append(line)
            if "[1/3]" in line:
                break
        time.sleep(1.0)
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C does: the command and its workers
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    err = "".join(seen) + err
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "distributed." not in err, err
    assert err.strip().splitlines()[-1] == "servo-press: interrupted"


def test_a_local_clusters_own_error_lines_stay_off_the_terminal(capfd):
    """A worker started here writes to this process's stderr; Dask's ERROR lines there (a heartbeat that lost the
    scheduler at Ctrl-C) must not reach the user, whose failures come through the futures."""
    import logging

    from dask.distributed import Client

    from calibration.fleet.cluster import local_cluster

    def _log_an_error() -> bool:
        logging.getLogger("distributed.worker").error("Failed to communicate with scheduler during heartbeat.")
        return True

    with local_cluster(1) as c, Client(c) as client:
        assert all(client.run(_log_an_error).values())
        time.sleep(0.2)
    err = capfd.readouterr().err
    assert "Failed to communicate" not in err, err


def test_ctrl_c_while_the_cluster_closes_lets_the_close_finish_then_stops(monkeypatch):
    """A Ctrl-C after the last log, while the client and the cluster close: raised inside the close it cut it short,
    and Python printed 'Exception ignored in ... WeakSet ... KeyboardInterrupt' when it landed in a weakref callback.
    The close now runs whole and the interrupt is raised after it (exit 130)."""
    from contextlib import contextmanager

    import dask.distributed

    from calibration.fleet import cluster as fleet
    from press_io.interrupts import Interrupted, exit_status

    closed = []

    @contextmanager
    def cluster(workers):
        yield object()
        os.kill(os.getpid(), signal.SIGINT)  # the user's Ctrl-C as the close begins
        total = 0
        for i in range(200_000):  # Python work of the close, where a raising handler would strike
            total += i
        closed.append(total)

    class Client:
        def __init__(self, cluster):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def map(self, fn, tasks, pure):
            return []

    monkeypatch.setattr(fleet, "local_cluster", cluster)
    monkeypatch.setattr(dask.distributed, "Client", Client)
    monkeypatch.setattr(dask.distributed, "as_completed", iter)
    with pytest.raises(KeyboardInterrupt) as stop:
        fleet.run_tasks(["a log"], 2, None, lambda task, res: None)
    assert closed == [sum(range(200_000))]  # the close ran to its end
    assert isinstance(stop.value, Interrupted) and exit_status(stop.value) == 130 and stop.value.__cause__ is None


# the program as its script runs it, with an exit hook that says when it runs and then takes its time (as Dask's can)
SLOW_EXIT = """
import atexit, os, sys, time
atexit.register(lambda: (os.write(2, b"exiting\\n"), time.sleep(120)))
from servo_press.cli import run
sys.argv = ["servo-press", *sys.argv[1:]]
run()
"""


def test_ctrl_c_while_the_program_exits_ends_it_quietly_with_130(tmp_path):
    """The command's work is done when the interpreter runs its exit hooks; a Ctrl-C then ended in 'Exception ignored
    in atexit callback' with a KeyboardInterrupt traceback."""
    proc = subprocess.Popen([sys.executable, "-c", SLOW_EXIT, "urdf", "--out", str(tmp_path / "press.urdf")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for line in proc.stderr:
            if line == "exiting\n":
                break
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130 and "Traceback" not in err and "Exception ignored" not in err, err
    assert err.strip().splitlines() == ["servo-press: interrupted"] and out.startswith("wrote "), (out, err)
