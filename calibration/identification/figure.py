"""Figure 5 of a calibration (figure5.png): measured, theoretical and calibrated motor torque over one turn."""
from __future__ import annotations

import numpy as np

from press_model.plots import subplots, tight_layout

from calibration.identification.run import Calibration


def figure5(cal: Calibration):
    """Measured (stroke mean and spread), theoretical and calibrated motor torque over one turn; with a validation
    log, a third panel with its measured curve and the predictions of both parameter sets."""
    obj, log = cal.objective, cal.log
    deg = np.degrees(obj.bm.theta)
    T0 = obj.torques(obj.problem.theoretical[None])[0]
    T1 = obj.torques(cal.best.x[None])[0]
    vp = cal.validation_problem
    if vp is None:
        fig, (ax, ax2) = subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    else:
        fig, (ax, ax2, ax3) = subplots(3, 1, figsize=(9, 9.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3, 2.5]})
    spread = np.nan_to_num(np.concatenate([lg.torque_spread for lg in cal.logs]) if len(cal.logs) > 1 else log.torque_spread)
    meas = obj.measured  # the stroke mean (of every log end to end when several were fitted)
    ax.fill_between(deg, (meas - spread) / 1e3, (meas + spread) / 1e3, color="0.8", label="measured +/- stroke spread")
    ax.plot(deg, meas / 1e3, color="k", lw=1.0, label=f"T_act ({'SYNTHETIC, ' if log.synthetic else ''}{log.strokes}-stroke mean)")
    ax.plot(deg, T0 / 1e3, color="C3", lw=1.2, ls="--", label=f"T_the (theoretical), RMSE {cal.before['rmse_Nm']:.0f} N m")
    ax.plot(deg, T1 / 1e3, color="C0", lw=1.2, label=f"T_cal ({cal.best.method}), RMSE {cal.after['rmse_Nm']:.0f} N m")
    for d in deg[~obj.peak_points][:1]:
        ax.axvline(d, color="0.5", lw=0.8, ls=":")
    ax.set_ylabel("motor torque per motor [kN m]")
    title = "Figure 5 analogue: servo motor torque over one cycle"
    ax.set_title(title + (" - SYNTHETIC drive log" if log.synthetic else ""), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2.plot(deg, (T0 - meas), color="C3", lw=0.9, ls="--", label="theoretical - measured")
    ax2.plot(deg, (T1 - meas), color="C0", lw=0.9, label="calibrated - measured")
    ax2.set_ylabel("error [N m]")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    ax2.set_xlim(0, 360 * max(1, len(cal.logs)))
    last = ax2
    if vp is not None:
        v, vo = cal.validation, vp.objective
        Tv = vo.torques(np.vstack([obj.problem.theoretical, cal.best.x]))
        vdeg = np.degrees(vo.bm.theta)
        ax3.plot(vdeg, vo.measured / 1e3, color="k", lw=1.0,
                 label=f"validation log ({'SYNTHETIC, ' if vp.log.synthetic else ''}{vp.log.strokes}-stroke mean, "
                       + (f"{100 * v['shared_samples_with_fit']:.3g} % of its samples fitted)" if v.get("shared_samples_with_fit")
                          else "not fitted)"))
        ax3.plot(vdeg, Tv[0] / 1e3, color="C3", lw=1.2, ls="--", label=f"theoretical, RMSE {v['rmse_before_Nm']:.0f} N m")
        ax3.plot(vdeg, Tv[1] / 1e3, color="C0", lw=1.2, label=f"calibrated, RMSE {v['rmse_after_Nm']:.0f} N m")
        ax3.set_ylabel("motor torque [kN m]")
        ax3.set_title("validation: a second log (another motion) predicted with both parameter sets", fontsize=9)
        ax3.legend(fontsize=8)
        ax3.grid(alpha=0.3)
        last = ax3
    last.set_xlabel("crank angle theta_c [deg]")
    tight_layout(fig)
    return fig
