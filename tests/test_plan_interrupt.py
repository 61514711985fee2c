"""Ctrl-C and SIGTERM while IPOPT runs the jerk-limited stage of `servo-press plan`.

CasADi catches the interrupt inside IPOPT and returns a status (User_Requested_Stop from its Python callbacks,
NonIpopt_Exception_Thrown from its own check of Ctrl-C); the planner took that for a failed solve and planned
toppra's jerk-free fallback in its place, so `plan` exited 0 and replaced an earlier good plan. Now the run stops:
exit 130 (SIGINT) or 143 (SIGTERM), one line `servo-press: interrupted`, the earlier plan byte for byte as it was.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from press_io.interrupts import Interrupted

DOOR_TEXT = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")

# `servo-press plan` in a subprocess whose IPOPT stops at its first iteration, in an iteration callback that says so on
# stderr and then waits: a signal sent after that line reaches the process while IPOPT runs, however loaded the machine
HELD_PLAN = r"""
import os, sys, time
import casadi as ca

real = ca.nlpsol


class Hold(ca.Callback):
    def __init__(self, nlp):
        ca.Callback.__init__(self)
        nx, ng, npar = nlp["x"].numel(), nlp["g"].numel(), nlp["p"].numel()
        self.sizes = {"x": nx, "f": 1, "g": ng, "lam_x": nx, "lam_g": ng, "lam_p": npar}
        self.construct("hold", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.sizes[ca.nlpsol_out(i)], 1)

    def eval(self, arg):
        os.write(2, b"IPOPT is iterating\n")
        time.sleep(600)  # until the test's signal
        return [0]


HOLDS = []


def nlpsol(name, plugin, nlp, opts):
    HOLDS.append(Hold(nlp))
    return real(name, plugin, nlp, {**opts, "iteration_callback": HOLDS[-1]})


ca.nlpsol = nlpsol
from servo_press.cli import run

sys.argv = ["servo-press", *sys.argv[1:]]
run()
"""


def snapshot(root: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in root.rglob("*")}


@pytest.fixture(scope="module")
def earlier_plan(door_panel_plan_run):
    """A good plan of the door panel (`servo-press plan`, run once a session: conftest.py); the tests copy it."""
    return door_panel_plan_run[0]


@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_ipopt_runs_stops_plan_and_keeps_the_earlier_plan(tmp_path, earlier_plan, sig, status):
    """The interrupted run plans the door panel on the coarsest knots a job may state: what is checked (the exit status,
    the one line, the earlier plan kept) is decided by where the signal lands, inside IPOPT, not by the knots; 5 degrees
    reach the IPOPT stage in a fraction of the shipped grid's path dynamics, toppra and problem build."""
    out = tmp_path / "plan"
    shutil.copytree(earlier_plan, out)
    job = tmp_path / "door_panel_coarse.toml"
    job.write_text(DOOR_TEXT.replace("[planning]\n", "[planning]\ngrid_step_deg = 5.0\n", 1), encoding="utf-8")
    before = snapshot(tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", HELD_PLAN, "plan", "--job", str(job), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as a terminal's job has it
    seen = []
    watchdog = threading.Timer(600, lambda: os.killpg(proc.pid, signal.SIGKILL))  # a run that never reaches IPOPT fails
    watchdog.start()
    try:
        for line in proc.stderr:
            seen.append(line)
            if line.startswith("IPOPT is iterating"):
                break
        assert seen and seen[-1].startswith("IPOPT is iterating"), "".join(seen)
        # Ctrl-C reaches the whole process group (the command and its figure helper); SIGTERM, as `kill` sends it, the command
        os.killpg(proc.pid, sig) if sig == signal.SIGINT else os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=240)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = "".join(seen) + err
    assert proc.returncode == status, err
    assert "Traceback" not in err and "CasADi" not in err and "WARNING" not in err, err
    assert err.strip().splitlines()[-1] == "servo-press: interrupted", err
    assert snapshot(tmp_path) == before  # the earlier plan byte for byte; no temporary folder, no lock left


def test_an_interrupt_that_casadi_swallows_inside_ipopt_is_raised_after_the_call(capfd):
    """Ctrl-C in IPOPT's own C code (no Python callback): CasADi stops IPOPT, returns NonIpopt_Exception_Thrown and
    prints a warning; call_solver raises the interrupt instead and keeps the warning off stderr."""
    from planning.optimal import call_solver

    n = 4000  # a long Rosenbrock valley and a tolerance never met: IPOPT runs until it is stopped
    x = ca.SX.sym("x", n)
    f = ca.sum1(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2)
    solver = ca.nlpsol("endless", "ipopt", {"x": x, "f": f},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 10 ** 7,
                        "ipopt.tol": 1e-30, "ipopt.acceptable_iter": 0, "ipopt.hessian_approximation": "limited-memory",
                        "ipopt.max_cpu_time": 300.0})  # a Ctrl-C that never arrives fails the test instead of hanging it
    main_thread = threading.main_thread().ident
    code = call_solver.__code__

    def interrupt_inside_the_solve():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # until this thread sees the main thread inside the solver call
            frame = sys._current_frames().get(main_thread)
            while frame is not None and frame.f_code is not code:
                frame = frame.f_back
            if frame is not None and "solver(**args)" in _line(frame):
                time.sleep(0.2)
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.01)

    t = threading.Thread(target=interrupt_inside_the_solve, daemon=True)
    t.start()
    with pytest.raises(Interrupted) as stop:
        call_solver(solver, x0=np.full(n, 0.5))
    t.join()
    assert stop.value.signum == signal.SIGINT and stop.value.exit_status == 130
    assert solver.stats()["return_status"] in ("NonIpopt_Exception_Thrown", "User_Requested_Stop")
    assert "KeyboardInterrupt" not in capfd.readouterr().err


def _line(frame) -> str:
    import linecache

    return linecache.getline(frame.f_code.co_filename, frame.f_lineno)
