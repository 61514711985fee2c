"""The 'urdf' command: the press's linkage as a URDF tree plus its loop-closure file."""
from __future__ import annotations

from pathlib import Path

from press_model.model import PressModel
from press_io.outputs import claim, file_out, refuse_overwrite_input
from press_model.press_data import load_press
from press_model.urdf import check_urdf_target, default_urdf_path, write_urdf


def urdf_job(press_arg: str | None, out_arg: str | None) -> tuple[Path, Path]:
    """The 'urdf' command: the URDF and loop file of the press ``press_arg`` at ``out_arg`` (default:
    :func:`default_urdf_path`); returns their paths. A linkage that cannot assemble, an input file and a file
    another press (or the user) made are refused."""
    file_out(out_arg)
    press = load_press(press_arg)
    PressModel(press)  # refuse to write a URDF of a linkage that cannot assemble
    out = Path(out_arg) if out_arg is not None else default_urdf_path(press)
    refuse_overwrite_input(out, [press_arg])
    with claim(out, str(out)):  # the URDF and its loop file come from one run
        check_urdf_target(press, out)  # never replace a file another press (or the user) made
        return write_urdf(press, out)
