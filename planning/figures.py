"""Figures 6 and 7 of the paper, for one plan or several (compare): torque with its limits; motor speed and acceleration.

matplotlib is imported when a figure is drawn, not with this module: `plan` and `compare` draw them in a figure worker
(:func:`figure_worker`), so the planning process itself never imports it."""
from __future__ import annotations

from dataclasses import dataclass

import gc
import math

import numpy as np

from press_io.forked import warm_process
from press_model.plots import legend_outside, pyplot, subplots, torque_limit_lines
from press_model.torque_limits import TorqueLimits


def _mark_stops(ax, stops) -> None:
    """Shade the stops on the way (``stops``: (start s, end s, label) each, :func:`planning.hold.stop_spans`)."""
    for k, (t0, t1, label) in enumerate(stops):
        ax.axvspan(t0, t1, color="0.85", zorder=0, label=label if k == 0 or label != stops[k - 1][2] else None)


def torque_figure(curves, limits: TorqueLimits, rated: float, title: str, stops=()):
    """Figure 6 analogue: motor torque per motor (kN m) against time with +/- T_max and +/- margin x T_max
    (:func:`torque_limit_lines`) and each curve's RMS vs T_rated (``rated``, N m); ``stops``: the stops on the way to
    shade (:func:`_mark_stops`). The legend stands beside the plot (:func:`legend_outside`). Returns the figure.

    ``curves``: list of (label, time_s, torque_Nm, rms_Nm).
    """
    fig, ax = subplots(figsize=(9, 4.8))
    _mark_stops(ax, stops)
    for k, (label, t, tm, rms) in enumerate(curves):
        ax.plot(t, tm / 1e3, color=f"C{k}", lw=1.2, label=f"{label}")
        ax.axhline(rms / 1e3, color=f"C{k}", ls=":", lw=1.2, label=f"{label}: cycle RMS {rms / 1e3:.2f} kN m")
    torque_limit_lines(ax, limits)
    ax.axhline(rated / 1e3, color="k", ls="-.", lw=1, label=f"T_rated = {rated / 1e3:.4g} kN m (thermal limit on the RMS)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("motor torque per motor [kN m]")
    ax.grid(alpha=0.3)
    legend_outside(ax)
    ax.set_title(title, fontsize=10)
    return fig


def speed_figure(curves, gear_ratio: float, max_speed_rpm: float, title: str, stops=()):
    """Figure 7 analogue: motor speed (rpm) and motor / crank angular acceleration against time; ``stops``: the stops on
    the way to shade (:func:`_mark_stops`).

    ``curves``: list of (label, time_s, crank_speed_rad_s, crank_accel_rad_s2).
    """
    fig, (ax1, ax2) = subplots(2, 1, figsize=(9, 6.5), sharex=True)
    _mark_stops(ax1, stops)
    _mark_stops(ax2, stops)
    for k, (label, t, sd, sdd) in enumerate(curves):
        ax1.plot(t, sd * gear_ratio * 60.0 / (2.0 * math.pi), color=f"C{k}", lw=1.2, label=label)
        ax2.step(t, sdd * gear_ratio, where="post", color=f"C{k}", lw=1.0, label=label)
    ax1.axhline(max_speed_rpm, color="C3", ls="--", lw=1, label=f"motor speed limit {max_speed_rpm:g} rpm")
    ax1.set_ylabel("motor speed [rpm]")
    ax1.grid(alpha=0.3)
    legend_outside(ax1)
    ax1.set_title(title, fontsize=10)
    ax2.set_ylabel("motor acceleration [rad/s^2]")
    sec = ax2.secondary_yaxis("right", functions=(lambda y: y / gear_ratio, lambda y: y * gear_ratio))
    sec.set_ylabel("crank acceleration [rad/s^2]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    return fig


def comparison_figure(rows, paper: tuple[float, float] | None, margin: float, title: str):
    """Bar chart: strokes per minute of each plan (beside the paper's two, labelled as the paper's, when ``paper`` is
    given: the reference press only), and each plan's peak |T_m| / T_max under both models, drawn to scale with T_max
    and the ``margin`` as lines: a bar above T_max is drawn whole and labelled with its value and the overload in %.
    Returns the figure."""
    fig, (ax1, ax2) = subplots(1, 2, figsize=(11, 4.2))
    labels = [r["plan"] for r in rows] + (["the paper's press:\ntheoretical", "the paper's press:\ncalibrated"] if paper else [])
    spm = [r["strokes_per_min"] for r in rows] + (list(paper) if paper else [])
    ax1.bar(range(len(spm)), spm, color=[f"C{k}" for k in range(len(rows))] + ["0.6", "0.4"][:len(spm) - len(rows)])
    ax1.set_xticks(range(len(spm)), labels, rotation=20, fontsize=8)
    ax1.set_ylim(min(spm) * 0.95, max(spm) * 1.02)
    ax1.set_ylabel("strokes per minute")
    for k, v in enumerate(spm):
        ax1.text(k, v, f"{v:.3f}", ha="center", va="bottom", fontsize=8)
    width = 0.35
    x = np.arange(len(rows))
    ratios = [(r["peak_ratio_theoretical_model"], r["peak_ratio_calibrated_model"]) for r in rows]
    for j, (model, off) in enumerate((("theoretical", -width / 2), ("calibrated", width / 2))):
        ax2.bar(x + off, [rt[j] for rt in ratios], width, color=f"C{j}", label=f"evaluated: {model} model")
        for k, rt in enumerate(ratios):
            over = f"\n{100 * (rt[j] - 1.0):+.0f} % over T_max" if rt[j] > 1.0 else ""
            ax2.text(x[k] + off, rt[j], f"{rt[j]:.3f}{over}", ha="center", va="bottom", fontsize=7,
                     color="C3" if rt[j] > margin * (1 + 1e-9) else "k")
    ax2.axhline(1.0, color="C3", ls="-", lw=1.2, label="T_max (the motor's peak torque)")
    ax2.axhline(margin, color="C3", ls="--", lw=1, label=f"{margin:g} T_max (the margin)")
    ax2.set_xticks(x, [r["plan"] for r in rows], fontsize=8)
    ax2.set_ylabel("peak |T_m| / T_max")
    top = max([1.0, margin] + [v for rt in ratios for v in rt])
    ax2.set_ylim(0.0, top * 1.15)  # from zero: the bars' heights are the ratios (nothing cut off above or below)
    legend_outside(ax2)
    fig.suptitle(title, fontsize=10)
    return fig


def pareto_figure(rows, title: str):
    """The front of ``plan --pareto``: strokes per minute and energy per stroke (MJ) against the grid's peak power (MW);
    ``rows`` pareto.csv's rows (planning.energy)."""
    ok = [r for r in rows if r["strokes_per_min"] == r["strokes_per_min"]]  # the infeasible last limit has no plan
    fig, ax1 = subplots(figsize=(8, 4.5))
    peak = [r["grid_peak_W"] / 1e6 for r in ok]
    ax1.plot(peak, [r["strokes_per_min"] for r in ok], "o-", color="C0", label="strokes per minute")
    ax1.set_xlabel("grid peak power [MW]")
    ax1.set_ylabel("strokes per minute", color="C0")
    ax1.grid(alpha=0.3)
    ax2 = ax1.twinx()
    ax2.plot(peak, [r["energy_per_stroke_J"] / 1e6 for r in ok], "s--", color="C1", label="energy per stroke (net, from the grid)")
    ax2.set_ylabel("energy per stroke [MJ]", color="C1")
    lines = ax1.get_lines() + ax2.get_lines()
    # below the plot: the right-hand axis holds the energy scale, and a legend inside covered the front's points
    ax1.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    ax1.set_title(title, fontsize=10)
    return fig


def _warm() -> None:
    gc.freeze()  # what the process inherits from the planner (~1M objects of its imports) is no garbage: never walked
    pyplot()


@dataclass
class Drawing:
    """Where a command's figures are drawn: ``worker`` a :func:`figure_worker` (None: drawn in this process, before the
    writer returns) and ``drawn`` the list the Futures of the figures handed to it are appended to, for the caller to
    wait for before its output folder is finished (None: each writer waits for its own). The same bytes either way."""

    worker: object = None
    drawn: list | None = None


def figure_worker():
    """:func:`press_model.plots.figure_worker` for a planning command (a process forked now that imports matplotlib
    and draws the figures given to :func:`press_model.plots.save_later`), with the objects it inherits frozen first:
    its collector need not walk the planner's (`plan`'s whole CPU 0.96 of drawing in its own process, 1.05 without the
    freeze; A/B pairs under load)."""
    return warm_process(_warm)


def slide_height_figure(t, height, opening: float, time_required: float, turning: list, title: str):
    """Slide height (m above BDC) against time (s) with the transfer's window: its opening height drawn, the times the
    slide is at or above it shaded, the turning points (or the dwell at TDC) marked.

    ``turning``: list of (label, time_s, height_m), A's labels starting "turning point A"; ``time_required``: the transfer's time per stroke (s)."""
    fig, ax = subplots(figsize=(9, 4.2))
    t, height = np.asarray(t, float), np.asarray(height, float)
    ax.plot(t, height, color="C0", lw=1.3, label="slide height")
    ax.axhline(opening, color="C2", ls="--", lw=1, label=f"transfer opening {opening:g} m (needs {time_required:g} s per stroke)")
    ax.fill_between(t, 0.0, 1.0, where=height >= opening - 1e-9, transform=ax.get_xaxis_transform(), color="C2", alpha=0.15,
                    lw=0, label="slide at or above the opening (transfer window)")
    for k, (label, tk, hk) in enumerate(turning):
        ax.plot([tk], [hk], marker="^" if label.startswith("turning point A") else "v", color="C3" if k < 2 else "C1", ms=8,
                ls="none", label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("slide height above BDC [m]")
    ax.grid(alpha=0.3)
    legend_outside(ax)
    ax.set_title(title, fontsize=10)
    return fig
