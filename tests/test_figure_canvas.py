"""The canvas figures are drawn on (press_model.figure_canvas) measures and draws text as matplotlib's own Agg canvas
does, within antialiasing, and press_model.plots places titles where matplotlib's automatic placement puts them."""
from __future__ import annotations

import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
import pytest
from PIL import Image

from press_model.plots import DPI, legend_outside, own_canvas, save, subplots

if not own_canvas():  # this matplotlib release draws on its own canvas (plots.CHECKED_MATPLOTLIB): nothing of ours to check
    pytest.skip("figures are drawn on matplotlib's own Agg canvas with this matplotlib release", allow_module_level=True)

from press_model import figure_canvas  # noqa: E402 (it subclasses Agg's private parts: imported only where checked)


def _panel(fig):
    ax = fig.subplots()
    t = np.linspace(0.0, 4.0, 200)
    ax.plot(t, np.sin(t), label="motor torque per motor")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("torque [kN m]")  # drawn turned by 90 degrees
    ax.set_xticks([0, 1, 2, 3, 4], ["zero", "one", "two", "three", "four"], rotation=20)
    ax.set_title("a title", fontsize=10)
    legend_outside(ax)
    return fig


def _pixels(fig) -> np.ndarray:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return np.asarray(Image.open(buf).convert("L"), dtype=float)


def test_texts_are_measured_as_matplotlib_measures_them():
    ours, theirs = figure_canvas.Renderer(10, 10, DPI), RendererAgg(10, 10, DPI)
    for text, size in (("time [s]", 10), ("+/-0.9 T_max = 24.7 kN m (the margin the plan keeps)", 7), ("0.25", 8)):
        prop = FontProperties(size=size)
        assert ours.get_text_width_height_descent(text, prop, False) == theirs.get_text_width_height_descent(text, prop, False)
        assert ours.get_text_width_height_descent(text, prop, False) == theirs.get_text_width_height_descent(text, prop, False)


def test_a_figure_draws_as_on_matplotlibs_canvas_within_antialiasing():
    reference = Figure(figsize=(6, 3.5))
    FigureCanvasAgg(reference)
    fig = Figure(figsize=(6, 3.5))
    figure_canvas.Canvas(fig)
    a, b = _pixels(_panel(reference)), _pixels(_panel(fig))
    assert a.shape == b.shape
    # every text stands where matplotlib draws it: ink within two pixels of the reference's ink (a string is placed on
    # whole pixels, its glyphs' shapes differ by antialiasing), and as much of it
    ink_a, ink_b = a < 128, b < 128

    def near(ink):
        for _ in range(2):
            ink = ink | np.roll(ink, 1, 0) | np.roll(ink, -1, 0) | np.roll(ink, 1, 1) | np.roll(ink, -1, 1)
        return ink

    assert (ink_b & ~near(ink_a)).sum() < 0.01 * ink_a.sum()
    assert (ink_a & ~near(ink_b)).sum() < 0.01 * ink_a.sum()
    assert abs(ink_a.sum() - ink_b.sum()) < 0.05 * ink_a.sum()
    assert np.abs(a - b).mean() < 2.0  # of 255: the strokes' edges differ, not the picture


def test_a_title_is_lifted_above_the_offset_text_as_matplotlib_lifts_it(tmp_path):
    def offset_axes(ax):
        ax.plot([0.0, 1.0], [1.0e6, 1.0e6 + 3.0])  # y ticks drawn as offsets from 1e6: "+1e6" above the axis
        ax.set_title("a title long enough to reach over the axis's offset text " * 2, fontsize=9)
        return ax

    reference = Figure(figsize=(5, 3))
    FigureCanvasAgg(reference)
    ref_ax = offset_axes(reference.subplots())
    reference.draw_without_rendering()
    fig, ax = subplots(figsize=(5, 3))
    offset_axes(ax)
    save(fig, tmp_path / "f.png")
    assert ref_ax.yaxis.get_offset_text().get_text()  # the case: an offset text the title meets
    assert ref_ax.title.get_position()[1] > 1.0  # matplotlib lifted it
    assert ax.title.get_position() == ref_ax.title.get_position()


def test_a_title_with_nothing_above_its_axes_stands_where_matplotlib_puts_it(tmp_path):
    reference = Figure(figsize=(5, 3))
    FigureCanvasAgg(reference)
    ref_axes = reference.subplots(2, 1, sharex=True)
    fig, axes = subplots(2, 1, figsize=(5, 3), sharex=True)
    for a in (*ref_axes, *axes):
        a.plot([0.0, 1.0], [0.0, 2.0])
        a.set_title("panel", fontsize=9)
    reference.draw_without_rendering()
    save(fig, tmp_path / "f.png")
    for a, b in zip(axes, ref_axes):
        assert a.title.get_position() == b.title.get_position()  # in axes coordinates: where the placement put it
