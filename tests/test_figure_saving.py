"""press_model.plots.save draws a figure once and keeps what matplotlib's savefig(bbox_inches="tight") keeps: the
same region (a legend beside the plot included), with nothing cut where something stands far outside the figure."""
from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from press_model.plots import DPI, legend_outside, save, subplots, tight_layout


def _tight_size(fig) -> tuple[int, int]:
    """(width, height) in pixels of the PNG matplotlib's own tight bounding box gives (the reference)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    return Image.open(buf).size


def _counting_draws(fig) -> list:
    """Count each drawing of ``fig`` (a list that gets one entry per Figure.draw)."""
    calls, draw = [], fig.draw

    def counted(renderer):
        calls.append(renderer)
        return draw(renderer)

    fig.draw = counted
    return calls


def _legend_beside():
    fig, ax = subplots(figsize=(6, 3.5))
    t = np.linspace(0.0, 4.0, 400)
    ax.plot(t, np.sin(t), label="a long label of a curve whose legend stands right of the plot")
    ax.axhline(0.5, ls="--", label="+/-0.9 T_max = 24.7 kN m (the margin the plan keeps)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("torque [kN m]")
    ax.set_title("title", fontsize=10)
    legend_outside(ax)
    return fig


def test_a_figure_is_drawn_once_over_the_region_the_tight_box_gives(tmp_path):
    reference = _tight_size(_legend_beside())
    fig = _legend_beside()
    draws = _counting_draws(fig)
    save(fig, tmp_path / "f.png")
    assert len(draws) == 1
    image = Image.open(tmp_path / "f.png")
    assert image.mode == "RGB" and image.info["dpi"] == pytest.approx((DPI, DPI), rel=1e-3)
    # the crop is the drawn pixels' box, the tight one that of the artists' boxes (text line heights): a few pixels
    assert np.all(np.abs(np.subtract(image.size, reference)) <= 4), (image.size, reference)
    assert reference[0] > 6 * DPI  # the legend beside the plot is in both


def test_a_note_far_outside_the_figure_is_drawn_where_it_stands(tmp_path):
    def noted():
        fig, ax = subplots(figsize=(4, 3))
        ax.plot([0, 1], [0, 1])
        ax.text(2.6, 0.5, "a note far right of the plot", transform=ax.transAxes)  # ~4.5 in beyond the figure's box
        return fig

    reference = _tight_size(noted())
    fig = noted()
    draws = _counting_draws(fig)
    save(fig, tmp_path / "f.png")
    assert len(draws) == 1
    assert np.all(np.abs(np.subtract(Image.open(tmp_path / "f.png").size, reference)) <= 4)


def test_what_reaches_beyond_the_drawn_region_is_drawn_again_over_the_tight_box(tmp_path):
    def reaching():
        fig, ax = subplots(figsize=(4, 3))
        ax.plot([0, 4], [0, 0.5], clip_on=False)  # a curve drawn on past its axes, 3 widths beyond them
        ax.set_xlim(0, 1)
        return fig

    reference = _tight_size(reaching())
    fig = reaching()
    draws = _counting_draws(fig)
    save(fig, tmp_path / "f.png")
    assert len(draws) == 2  # drawn over the region, reached its edge, drawn again over the tight box
    # the same tight box, measured by matplotlib at the figure's dpi here and at the PNG's in savefig: a pixel apart
    assert np.all(np.abs(np.subtract(Image.open(tmp_path / "f.png").size, reference)) <= 1)


def test_tight_layout_places_the_axes_as_matplotlib_does_and_leaves_no_engine():
    def two_panels():
        fig, axes = subplots(2, 1, figsize=(5, 4))
        for ax in axes:
            ax.plot([0, 1e4], [0, 1])
            ax.set_ylabel("a label\non two lines")
            ax.set_title("a title")
        return fig

    ours, theirs = two_panels(), two_panels()
    tight_layout(ours)
    theirs.tight_layout()
    assert ours.get_layout_engine() is None  # savefig measures no figure before drawing it
    for a, b in zip(ours.axes, theirs.axes):
        assert np.allclose(a.get_position().bounds, b.get_position().bounds)


def test_a_matplotlib_release_not_checked_draws_on_matplotlibs_own_canvas_and_title_placement(tmp_path, monkeypatch):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from press_model import plots

    monkeypatch.setattr(plots, "CHECKED_MATPLOTLIB", ())
    fig, ax = plots.subplots(figsize=(4, 3))
    ax.plot([0.0, 1.0], [1.0e6, 1.0e6 + 3.0])
    ax.set_title("a title")
    assert type(fig.canvas) is FigureCanvasAgg and ax._autotitlepos  # matplotlib's own canvas and placement
    plots.save(fig, tmp_path / "plain.png")
    assert (tmp_path / "plain.png").stat().st_size > 1000
