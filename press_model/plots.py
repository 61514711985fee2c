"""Figures. Matplotlib is used headless (Agg), imported on first use, and every figure is saved atomically as PNG.

A figure is made by :func:`subplots` (a Figure on its own Agg canvas, :mod:`press_model.figure_canvas`: no pyplot,
no figure manager) and written by :func:`save`, which draws it once. A command whose figures can be drawn beside its
own work hands them to :func:`figure_worker`, a process forked at its start that imports matplotlib at once (~0.35 s
of CPU) and draws them while the command computes.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import AbstractContextManager
from pathlib import Path

import numpy as np

from press_io.forked import warm_process
from press_io.outputs import atomic_write

from .torque_limits import TorqueLimits

DPI = 130  # pixels per inch of every PNG
PAD = 0.1  # inches of background around what a figure draws (savefig's pad_inches)
PNG_LEVEL = 3  # zlib level: half level 6's time for ~10 % more bytes
MARGIN = 0.5  # inches drawn around the figure's box and its axes' boxes: room for their tick labels and axis labels


def pyplot():
    """matplotlib.pyplot with the headless Agg backend, imported on the first call: what a figure worker imports at
    its start (it holds matplotlib's Figure and Agg canvas, with which :func:`subplots` draws)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


@functools.cache  # asked at every figure; the installed release does not change within a process
def matplotlib_release() -> tuple[int, ...]:
    """The installed matplotlib's (major, minor) release, () if its version string is not numbers."""
    from importlib.metadata import version

    try:
        return tuple(int(part) for part in version("matplotlib").split(".")[:2])
    except ValueError:  # pragma: no cover - an unusual version string: matplotlib's own canvas
        return ()


# :mod:`press_model.figure_canvas` subclasses Agg's renderer through its private parts, and :func:`drawn_image` sets
# an axes' private ``_autotitlepos``: both are checked (tests/test_figure_canvas.py) on these matplotlib releases only.
# Any other release draws on matplotlib's own Agg canvas with its own title placement (the same figures, slower)
CHECKED_MATPLOTLIB = ((3, 11),)


def own_canvas() -> bool:
    """Whether figures are drawn on :class:`press_model.figure_canvas.Canvas` (the installed matplotlib is a release in
    :data:`CHECKED_MATPLOTLIB`); False: on matplotlib's FigureCanvasAgg."""
    return matplotlib_release() in CHECKED_MATPLOTLIB


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float], **kw):
    """A new figure of ``figsize`` (inches) on its own Agg canvas (:class:`press_model.figure_canvas.Canvas`: texts
    measured and rasterised once per process, where :func:`own_canvas`; else matplotlib's FigureCanvasAgg) and its
    axes, as ``Figure.subplots(nrows, ncols, **kw)`` gives them; returns (figure, axes). Nothing outside holds the
    figure (pyplot's manager is not used), so it needs no closing."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not own_canvas():
        fig = Figure(figsize=figsize)
        FigureCanvasAgg(fig)
        return fig, fig.subplots(nrows, ncols, **kw)
    from .figure_canvas import Canvas

    # titles at the axes' top (their own padding above): matplotlib would measure every tick label of the y axis at
    # each draw to see whether its offset text meets the title (~25 % of a drawing); drawn_image checks it after
    with matplotlib.rc_context({"axes.titley": 1.0}):
        fig = Figure(figsize=figsize)
        Canvas(fig)
        return fig, fig.subplots(nrows, ncols, **kw)


def save(fig, path: Path) -> None:
    """Write the figure as a PNG atomically: drawn once at :data:`DPI`, cropped to what it draws with :data:`PAD`
    of background around (the region savefig's bbox_inches="tight" gives, without its second drawing), no metadata
    (reruns give identical bytes)."""
    image = drawn_image(fig)
    atomic_write(path, lambda tmp: image.save(tmp, format="png", compress_level=PNG_LEVEL, dpi=(DPI, DPI)), suffix=".png")


def drawn_image(fig):
    """The figure drawn at :data:`DPI` and cropped to what it draws plus :data:`PAD`: a PIL RGB image.

    The figure is drawn once over :func:`drawn_region` and cropped to the pixels that differ from the background
    (drawn again with matplotlib's automatic title placement where :func:`_titles_stand_free` finds it could matter).
    Where the drawing reaches that region's edge (something lies beyond it), the region is matplotlib's tight box of
    the figure instead (measured, then drawn: as savefig's bbox_inches="tight")."""
    from PIL import Image

    rgba = _draw(fig, drawn_region(fig))
    if _titles_fixed(fig) and not _titles_stand_free(fig):
        for ax in fig.axes:
            ax._autotitlepos = True  # matplotlib's own placement (as without the rcParam subplots sets): titles lifted
        rgba = _draw(fig, drawn_region(fig))
    px = rgba.view(np.uint32)[..., 0]
    rows = np.flatnonzero(_inked(px, axis=1))
    if len(rows) == 0:
        return _rgb(rgba)
    cols = np.flatnonzero(_inked(px[rows[0]:rows[-1] + 1], axis=0, background=px[0, 0]))
    if rows[0] == 0 or cols[0] == 0 or rows[-1] == px.shape[0] - 1 or cols[-1] == px.shape[1] - 1:
        tight = fig.get_tightbbox(fig.canvas.get_renderer()).padded(PAD)
        return _rgb(_draw(fig, tight))
    pad = round(PAD * DPI)
    out = Image.new("RGB", (cols[-1] - cols[0] + 1 + 2 * pad, rows[-1] - rows[0] + 1 + 2 * pad), tuple(int(v) for v in rgba[0, 0, :3]))
    out.paste(_rgb(rgba, (cols[0], rows[0], cols[-1] + 1, rows[-1] + 1)), (pad, pad))
    return out


def _inked(px: np.ndarray, axis: int, background=None) -> np.ndarray:
    """Per row (``axis`` 1) or column (0) of ``px`` (one uint32 per RGBA pixel), whether it holds a pixel other than
    ``background`` (default: the top left pixel): its least or greatest value differs from it (two reductions, no
    array of the pixels' comparisons)."""
    background = px[0, 0] if background is None else background
    return (px.min(axis=axis) != background) | (px.max(axis=axis) != background)


def _rgb(rgba: np.ndarray, box: tuple | None = None):
    """The (rows, columns, 4) uint8 RGBA pixels, or their ``box`` (left, top, right, bottom), as a PIL RGB image
    (converted by Pillow: numpy's copy of every third byte took ~30 ms a figure)."""
    from PIL import Image

    image = Image.frombuffer("RGBA", (rgba.shape[1], rgba.shape[0]), rgba, "raw", "RGBA", 0, 1)
    return (image if box is None else image.crop(box)).convert("RGB")


def _titles_fixed(fig) -> bool:
    """Whether :func:`subplots` fixed the figure's titles at its axes' top (a figure on :class:`figure_canvas.Canvas`);
    False: matplotlib places them itself."""
    return type(fig.canvas).__module__ == "press_model.figure_canvas"


def _titles_stand_free(fig) -> bool:
    """Whether the figure, drawn once, has nothing that matplotlib's automatic title placement would lift a title
    above: no axes with a title beside an axes with an offset text on its y axis (a "1e6" above it) or x tick labels
    or x label on top. Returns True where titles fixed at the axes' top stand where matplotlib would put them."""
    if not any(ax.get_title(loc) for ax in fig.axes for loc in ("center", "left", "right")):
        return True
    for ax in fig.axes:
        offset = ax.yaxis.get_offset_text()
        if offset.get_visible() and offset.get_text():
            return False
        if ax.xaxis.get_tick_params().get("labeltop") or ax.xaxis.get_label_position() == "top":
            return False
    return True


def drawn_region(fig):
    """The part of the figure's plane :func:`drawn_image` draws, a Bbox in inches: the figure's box, its axes' boxes
    and its texts (titles, notes, labels of bars) and every legend anchored off its axes (:func:`legend_outside`),
    each where it stands, widened by :data:`MARGIN`. A legend inside its axes ("best" among them) is not measured."""
    from matplotlib.transforms import Bbox

    w, h = fig.get_size_inches()
    boxes = [Bbox.from_bounds(0.0, 0.0, w, h)] + [Bbox.from_bounds(*np.multiply(ax.get_position().bounds, (w, h, w, h)))
                                                  for ax in fig.axes]
    legends = [(lg, fig.bbox) for lg in fig.legends] + [(ax.get_legend(), ax.bbox) for ax in fig.axes]
    outside = [t for t in (*fig.texts, *(t for ax in fig.axes for t in ax.texts)) if t.get_visible()]
    outside += [lg for lg, parent in legends if lg is not None and lg.get_bbox_to_anchor().bounds != parent.bounds]
    if outside:
        renderer, inches = fig.canvas.get_renderer(), fig.dpi_scale_trans.inverted()
        boxes += [a.get_window_extent(renderer).transformed(inches) for a in outside]
    return Bbox.union(boxes).padded(MARGIN)


def tight_layout(fig) -> None:
    """Place the figure's axes so that their labels and titles do not overlap (``Figure.tight_layout()``'s default
    padding), leaving the figure without a layout engine: with one set, savefig would measure the whole figure again
    before drawing it."""
    from matplotlib.layout_engine import TightLayoutEngine

    TightLayoutEngine().execute(fig)


def _draw(fig, region) -> np.ndarray:
    """The figure drawn once at :data:`DPI` over ``region`` (a Bbox in inches of the figure), as an (rows, columns, 4)
    uint8 RGBA array, rows from the top."""
    import io

    from matplotlib.transforms import Bbox

    # whole pixels and a half: the canvas's size is the region's in pixels truncated, known here without rounding doubt
    width, height = int(region.width * DPI) + 0.5, int(region.height * DPI) + 0.5
    region = Bbox.from_bounds(region.x0, region.y0, width / DPI, height / DPI)
    buf = io.BytesIO()
    fig.savefig(buf, format="rgba", dpi=DPI, bbox_inches=region, pad_inches=0)
    return np.frombuffer(buf.getbuffer(), np.uint8).reshape(int(height), int(width), 4)


def figure_worker() -> AbstractContextManager[ProcessPoolExecutor | None]:
    """A process, forked now, that imports matplotlib at once and then draws the figures given to :func:`save_later`
    (None where the system cannot fork)."""
    return warm_process(pyplot)


def save_later(worker: ProcessPoolExecutor | None, make: Callable, args: tuple, path: Path) -> Future:
    """``save(make(*args), path)`` in ``worker`` while the caller goes on, or now without one; returns its Future
    (its result() raises what the drawing raised). The same bytes either way."""
    if worker is not None:
        return worker.submit(_make_and_save, make, args, path)
    done = Future()
    _make_and_save(make, args, path)
    done.set_result(None)
    return done


def _make_and_save(make: Callable, args: tuple, path: Path) -> None:
    save(make(*args), path)


def legend_outside(ax, **kw) -> None:
    """The axes' legend beside the plot, right of it, where it covers no curve (a legend inside covered the torque
    near T_max and the slide near the opening)."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kw)


def torque_limit_lines(ax, limits: TorqueLimits, scale: float = 1e-3, unit: str = "kN m") -> None:
    """+/- T_max (solid) and +/- the margin (dashed) on ``ax``, both labelled with their value: the limit the motor
    cannot pass and the one the plan keeps. ``scale``: the axis unit per N m (kN m: 1e-3; T_max ratios: 1 / T_max)."""
    t_max, lim = limits.peak_torque * scale, limits.verdict * scale
    ax.axhline(t_max, color="C3", ls="-", lw=1.2, label=f"+/-T_max = {t_max:.4g} {unit} (the motor's peak torque)")
    ax.axhline(-t_max, color="C3", ls="-", lw=1.2)
    ax.axhline(lim, color="C3", ls="--", lw=1, label=f"+/-{limits.margin:g} T_max = {lim:.4g} {unit} (the margin the plan keeps)")
    ax.axhline(-lim, color="C3", ls="--", lw=1)


def cycle_figure(cycle, limits: TorqueLimits, rated: float, title: str):
    """Motor torque (with T_max, the planner's torque margin of ``limits`` and the thermal limit) and slide motion
    against crank angle."""
    deg = np.degrees(cycle.theta)
    fig, (ax1, ax2) = subplots(2, 1, figsize=(8, 6.5), sharex=True)
    ax1.plot(deg, cycle.motor_torque / 1e3, color="C0", label="motor torque (per motor)")
    torque_limit_lines(ax1, limits)
    rms = cycle.rms_motor_torque()
    ax1.axhline(rms / 1e3, color="C2", ls=":", lw=1.2, label=f"cycle RMS {rms / 1e3:.2f} kN m")
    ax1.axhline(rated / 1e3, color="C1", ls="-.", lw=1, label=f"T_rated = {rated / 1e3:.4g} kN m (thermal limit on the RMS)")
    ax1.set_ylabel("torque [kN m]")
    legend_outside(ax1)
    ax1.grid(alpha=0.3)
    ax1.set_title(title, fontsize=10)
    ax2.plot(deg, cycle.height, color="C0", label="slide height above BDC [m]")
    ax2.set_ylabel("H [m]")
    ax3 = ax2.twinx()
    ax3.plot(deg, cycle.height_dot, color="C1", label="slide velocity [m/s]")
    ax3.set_ylabel("dH/dt [m/s]")
    ax2.set_xlabel("crank angle theta_c [deg]")
    ax2.grid(alpha=0.3)
    lines = ax2.get_lines() + ax3.get_lines()
    ax2.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="upper left")
    ax2.set_xlim(0, 360)
    return fig


def linkage_figure(pm, crank_angles_deg, title: str):
    """The linkage drawn from the Pinocchio model at a few crank angles (the paper's Figure 2 analogue).

    Each body is drawn as the polygon of its joint points (a triangle for link 4), the slide as a box.
    """
    import math

    import pinocchio as pin

    from .kinematics import solve_position, warm_start
    from .model import Workspace

    ws = Workspace(pm)
    fig, ax = subplots(figsize=(7, 7.5))
    press = pm.press
    for k, deg in enumerate(crank_angles_deg):
        th = math.radians(deg)
        q = solve_position(pm, ws, th, warm_start(pm, th))
        pin.framesForwardKinematics(pm.model, ws.data, q)
        colour = f"C{k}"
        for bname, body in press.bodies.items():
            xy = np.array([ws.data.oMf[pm.frame_id[(bname, p)]].translation[:2] for p in body.points])
            if len(xy) > 2:
                xy = np.vstack([xy, xy[:1]])
            ax.plot(xy[:, 0], xy[:, 1], "-o", color=colour, ms=3, lw=1.6 if bname != press.slide_body else 3,
                    label=f"theta_c = {deg:g} deg" if bname == next(iter(press.bodies)) else None)
    for pname, p in press.frame_points.items():
        ax.plot(*p, "ks", ms=6)
        ax.annotate(pname, p, textcoords="offset points", xytext=(5, 5), fontsize=9)
    ax.axvline(press.frame_points.get("guide", np.zeros(2))[0], color="0.6", lw=0.8, ls="--")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title, fontsize=10)
    return fig


def power_figure(cols: dict, window: tuple[float, float], title: str):
    """Power over the cycle (MW: shaft of all motors, DC link, grid, brake resistor, storage), the DC-link voltage with
    its window (V) and, with a storage, its stored energy (MJ, right-hand axis of the lower panel); ``cols`` the columns
    of power.csv. Returns the figure."""
    t = cols["time_s"]
    fig, (ax1, ax2) = subplots(2, 1, figsize=(9, 6.5), sharex=True, height_ratios=(2, 1))
    for k, (key, label) in enumerate((("shaft_W", "shaft (all motors)"), ("dc_link_W", "drives from the DC link"),
                                      ("grid_W", "grid"), ("brake_resistor_W", "brake resistor"), ("storage_W", "storage (discharging > 0)"))):
        if key in cols and np.any(cols[key]):
            ax1.plot(t, np.asarray(cols[key]) / 1e6, color=f"C{k}", lw=1.2 if key != "grid_W" else 1.8, label=label)
    ax1.axhline(0.0, color="k", lw=0.6)
    ax1.set_ylabel("power [MW] (drawn > 0, returned < 0)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7, loc="best")
    ax1.set_title(title, fontsize=10)
    ax2.plot(t, cols["dc_link_voltage_V"], color="C0", lw=1.2, label="DC-link voltage")
    for v in window:
        ax2.axhline(v, color="C3", ls="--", lw=1)
    ax2.set_ylabel("DC link [V]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    handles = [h for h in ax2.get_lines() if not h.get_label().startswith("_")]
    if np.any(cols.get("storage_energy_J", 0.0)):  # the store's state beside the link's: what its power curve did to it
        ax3 = ax2.twinx()
        handles += ax3.plot(t, np.asarray(cols["storage_energy_J"]) / 1e6, color="C4", lw=1.2, label="stored energy (storage)")
        ax3.set_ylabel("stored energy [MJ]", color="C4")
    ax2.legend(handles, [h.get_label() for h in handles], fontsize=7, loc="best")
    return fig
