"""The planner's import of toppra leaves matplotlib out, and figures drawn in the figure worker are the same bytes."""
import filecmp
import subprocess
import sys
from pathlib import Path

from planning.figures import Drawing, figure_worker
from planning.report import write_plan_outputs
from press_model.jobs import load_job

PROBE = """
import sys
import planning.report, planning.compare  # toppra comes in through planning.toppra_solve
assert "toppra" in sys.modules, "toppra not imported"
print("matplotlib" in sys.modules, "matplotlib.pyplot" in sys.modules)
import toppra.algorithm.algorithm as alg
import matplotlib.pyplot as plt
print(hasattr(plt, "subplots"), callable(alg.plt.figure), plt.__file__ is not None)
"""


def test_planning_imports_toppra_without_matplotlib_and_pyplot_stays_usable():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "False False"  # toppra's own `import matplotlib.pyplot` did not load it
    assert out[1] == "True True True"  # a later import gets the real pyplot; toppra's stand-in forwards to it


def test_figures_drawn_in_the_worker_are_the_same_bytes(tmp_path, ref_model, door_panel_plan, door_panel_written):
    # the shipped door panel's plan and its outputs drawn here, in the writing process (conftest.py: planned once a
    # worker, written once a suite by write_plan_outputs with the same arguments as below but the drawing)
    pm, job, plan, here = ref_model, load_job("door-panel"), door_panel_plan, door_panel_written[0]
    with figure_worker() as worker:
        drawn = []
        write_plan_outputs(pm, job, plan, tmp_path / "worker", {}, "test", None, Drawing(worker, drawn))
        assert len(drawn) == 3  # torque.png, speed.png, power.png
        for f in drawn:
            f.result()
    for name in ("torque.png", "speed.png", "power.png", "profile.csv", "cam_table.csv", "power.csv", "summary.json"):
        assert filecmp.cmp(Path(here / name), Path(tmp_path / "worker" / name), shallow=False), name
