"""The lack-of-fit test and the score tests of calibration/identification/adequacy.py on curves with a known answer (no press model):
its false-alarm rate on adequate data, its power on a misfit, coloured noise told from misfit, and the size a score
test implies for a shift it was given."""
import math

import numpy as np
import pytest
from scipy import stats

from calibration.identification.adequacy import Candidate, Suspects, assess, effective_dof, lag1, regress, score_test, shift_columns
from press_model.cycle import crank_grid

TH = crank_grid(1.0)
CURVE = 8000.0 * np.sin(TH) + 3000.0 * np.cos(2 * TH) + 1500.0 * np.sin(3 * TH + 0.4)
MASK = np.abs(TH - 2.0) > 0.3  # a die-contact-like window left out


def strokes(rng, sigma=150.0, S=3, rho=0.0, extra=0.0):
    """S strokes of CURVE + extra with noise on the grid: white, or AR(1) along the grid with lag-one rho."""
    e = rng.normal(0.0, sigma, (S, TH.size))
    if rho:
        for i in range(1, TH.size):
            e[:, i] = rho * e[:, i - 1] + math.sqrt(1 - rho * rho) * e[:, i]
    return CURVE + extra + e


def test_false_alarm_rate_of_the_lack_of_fit_test_is_its_level():
    """With the true curve as the model, p is uniform: at 5 % the test rejects about 5 % of 400 logs (binomial 99 %
    range 2.2-8.3 %)."""
    rng = np.random.default_rng(11)
    p = []
    for _ in range(400):
        Y = strokes(rng)
        p.append(assess(Y, Y.mean(axis=0), CURVE, MASK, 0, 0.05).p_value)
    rate = np.mean(np.array(p) < 0.05)
    lo, hi = stats.binom.ppf([0.005, 0.995], 400, 0.05) / 400
    assert lo <= rate <= hi, rate


def test_misfit_of_half_the_noise_of_the_mean_is_found():
    """A smooth misfit whose RMS is the noise of the three-stroke mean is rejected, and the ratio says how big it is."""
    rng = np.random.default_rng(12)
    bump = 150.0 / math.sqrt(3) * math.sqrt(2) * np.sin(5 * TH)  # RMS = noise of the mean
    Y = strokes(rng)
    a = assess(Y, Y.mean(axis=0), CURVE + bump, MASK, 0, 0.01)
    assert not a.adequate and a.p_value < 1e-6
    assert 1.6 < a.lack_of_fit_ratio < 2.5  # E[F] = 1 + misfit / noise variance of the mean = 2
    assert a.residual_lag1 > 0.5 > abs(a.pure_error_lag1)  # smooth: neighbours alike, unlike the noise


def test_coloured_noise_is_not_model_error():
    """AR(1) noise (lag-one 0.8 along the grid) with the true curve: the pure error sees the colour, the residual's
    lag-one matches it, and the F test with its reduced degrees of freedom keeps its level (at most twice it over 200)."""
    rng = np.random.default_rng(13)
    rej, rho = 0, []
    for _ in range(200):
        Y = strokes(rng, rho=0.8)
        a = assess(Y, Y.mean(axis=0), CURVE, MASK, 0, 0.05)
        rej += a.p_value < 0.05
        rho.append(a.pure_error_lag1)
        assert a.noise_coloured
    assert abs(np.mean(rho) - 0.8) < 0.05
    assert rej / 200 <= 0.10
    # without the correction for colour the same F would reject far more often: its dof are what keep the level
    assert effective_dof(300, 0.8) < 0.25 * 300


def test_lag1_pools_strokes_and_skips_pairs_outside_the_mask():
    x = np.tile(np.arange(10.0), (2, 1))
    m = np.ones(10, bool)
    m[5] = False
    r, pairs = lag1(x, m)
    assert pairs == 2 * 8  # 10 periodic pairs per row, less the two that touch point 5
    assert r > 0.5


def test_score_test_recovers_a_delay_from_the_shifted_curve():
    """A curve delayed exactly (T(theta - omega d) with a varying speed) gives the delay the first-order column implies."""
    omega = 1.2 * (1 - 0.4 * np.cos(TH - 2.2))
    d = 0.004
    f = lambda th: 8000.0 * np.sin(th) + 3000.0 * np.cos(2 * th)
    measured = f(TH - omega * d)
    model = f(TH)
    delay, offset = shift_columns(TH, omega, model)
    J = np.column_stack([model, np.ones_like(TH)])  # two nuisance "parameters": a gain and an offset
    rng = np.random.default_rng(3)
    resid = measured - model + rng.normal(0, 5.0, TH.size)
    t = score_test(resid, J, Candidate("channel_delay", "delay", delay[:, None], "ms", 1e3), MASK, 0.01)
    assert t.significant and abs(t.size - 4.0) < 0.2 and t.size_std < 0.1
    # an effect that is not there: its t stays small
    t2 = score_test(rng.normal(0, 5.0, TH.size), J, Candidate("x", "x", np.sin(7 * TH)[:, None], "1", 1.0), MASK, 0.01)
    assert not t2.significant


def test_regress_coefficients_on_a_known_linear_model():
    """y = J a + Z b + noise: the Z coefficients and their standard errors (checked against the textbook OLS formula)."""
    rng = np.random.default_rng(4)
    J = np.column_stack([np.sin(TH), np.cos(TH)])
    Z = np.column_stack([np.sin(4 * TH), TH ** 2])
    b_true = np.array([30.0, -2.0])
    y = J @ np.array([5.0, 1.0]) + Z @ b_true + rng.normal(0, 10.0, TH.size)
    b, V, dof = regress(y, J, Z, np.ones(TH.size, bool))
    X = np.column_stack([J, Z])
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ beta
    cov = np.linalg.inv(X.T @ X) * (e @ e) / (len(y) - 4)
    assert np.allclose(b, beta[2:])
    r1, _ = lag1(e, np.ones(TH.size, bool))
    infl = (1 + r1) / (1 - r1) if r1 > 0 else 1.0
    assert np.allclose(V, cov[2:, 2:] * infl)
    assert np.all(np.abs(b - b_true) < 4 * np.sqrt(np.diag(V)))


def test_too_few_points_are_refused():
    Y = np.tile(CURVE, (3, 1))
    with pytest.raises(ValueError):
        assess(Y, CURVE, CURVE, np.zeros(TH.size, bool), 2, 0.01)


def test_a_misfit_the_parameters_can_absorb_is_no_lack_of_fit():
    """A model curve off by what a parameter change undoes (a gain and a constant, columns of J) is not called
    inadequate: the test asks what no parameter can absorb; without J the same curve is rejected."""
    rng = np.random.default_rng(14)
    Y = strokes(rng)
    model = 1.02 * CURVE + 40.0  # 2 % gain and 40 N m: far beyond the noise of the mean
    J = np.column_stack([CURVE, np.ones_like(TH)])
    assert assess(Y, Y.mean(axis=0), model, MASK, 2, 0.01, Suspects(J)).adequate
    assert not assess(Y, Y.mean(axis=0), model, MASK, 2, 0.01).adequate


def test_bootstrap_blocks_hold_the_jobs_number_of_noise_correlation_lengths():
    """White noise: the job's block_deg; AR(1) noise of lag-one rho: block_noise_lengths correlation lengths
    (-1 / ln rho grid points each), from the job, not a number in the code."""
    from calibration.identification.run import block_points
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job
    from press_model.settings_fields import replaced

    cs = CalibrationSettings.from_job(load_job("cushion-test"))
    step_deg = math.degrees(TH[1] - TH[0])
    assert block_points(cs, TH, 0.0) == round(cs.bootstrap.block_deg / step_deg)
    length = -1.0 / math.log(0.97)  # grid points
    assert block_points(cs, TH, 0.97) == math.ceil(cs.bootstrap.block_noise_lengths * length)
    assert block_points(replaced(cs, {"bootstrap.block_noise_lengths": 10.0}), TH, 0.97) == math.ceil(10.0 * length)


def test_the_bootstrap_blocks_keep_the_variance_of_a_fitted_models_estimate_under_white_noise():
    """A least-squares fit of six smooth terms to white noise on the grid (a die-contact window kept in place): the
    refits on its residual, block-resampled in the blocks the job's settings choose for it (block_points with the
    residual's own lag-one correlation), scatter as the estimate does, (X^T X)^-1 sigma^2 up to (n - 6) / n. Long blocks
    of a fitted residual lose what the fit absorbed along the smooth directions (20-point blocks kept 0.64-0.69 of it)."""
    from calibration.identification.bootstrap import block_resample
    from calibration.identification.run import block_points
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job

    cs = CalibrationSettings.from_job(load_job("cushion-test"))
    fixed = ~MASK
    X = np.column_stack([np.ones_like(TH), np.cos(TH), np.sin(TH), np.cos(2 * TH), np.sin(2 * TH), np.cos(3 * TH)])[MASK]
    exact = np.diag(np.linalg.inv(X.T @ X))  # sigma = 1
    rng = np.random.default_rng(5)
    ratios = []
    for _ in range(100):
        y = rng.normal(0.0, 1.0, TH.size)
        resid = np.zeros(TH.size)
        resid[MASK] = y[MASK] - X @ np.linalg.lstsq(X, y[MASK], rcond=None)[0]
        block = block_points(cs, TH, 0.0, lag1(resid, MASK)[0])
        refits = np.array([np.linalg.lstsq(X, block_resample(resid, fixed, block, rng)[MASK], rcond=None)[0] for _ in range(60)])
        ratios.append(refits.var(axis=0, ddof=1) / exact)
    ratio = np.mean(ratios, axis=0)  # each about 0.98 +- 0.02
    assert np.all((ratio > 0.9) & (ratio < 1.1)), ratio


def test_the_lost_motion_test_on_bin_means_of_unequal_noise_keeps_its_t_at_unit_scale():
    """Bin means whose noise variance follows the crank's speed (fewer samples a degree where it turns fast), fastest
    where the curve reverses, where the lost motion's column lives: weighted by their samples (``bin_weight``), the
    lost motion's t over 600 logs has the spread of a t (RMS within 0.90-1.08; unweighted 1.15-1.18 on two seeds)."""
    from calibration.identification.adequacy import candidate_columns

    rng = np.random.default_rng(5)
    speed = 1.0 + 0.9 * np.cos(2.0 * TH)  # rad/s; 1.9 where CURVE's sin(TH) part reverses, 0.1 between
    J = np.column_stack([CURVE, np.cos(TH), np.ones(TH.size)])  # a scale, a shape and a level the "parameters" take
    cands = [c for c in candidate_columns(TH, speed, CURVE, 32.0, 1e4) if c.name == "backlash"]
    assert cands and cands[0].binned
    ts = []
    for _ in range(600):
        Y = CURVE + rng.normal(0.0, 40.0, (3, TH.size)) * np.sqrt(speed)
        mean = Y.mean(axis=0)
        a = assess(Y, mean, CURVE, MASK, 3, 0.01, Suspects(J, cands, binned=mean, bin_weight=1.0 / speed))
        ts.append({t.name: t for t in a.tests}["backlash"].t)
    rms = math.sqrt(float(np.mean(np.square(ts))))
    assert 0.90 < rms < 1.08, rms


def test_a_model_curve_error_it_states_is_no_lack_of_fit_and_one_it_does_not_state_is():
    """A model curve off by a smooth error of about twice the noise of the mean (RMS) over a tenth of the turn (a crank motion's
    error where a ramp ends) is NOT ADEQUATE as an exact curve, adequate with that error's variance stated beside it;
    the same error elsewhere, not stated, is still found."""
    rng = np.random.default_rng(14)
    Y = strokes(rng)
    near = np.abs(TH - 4.0) < 0.3
    err = np.where(near, 3.0 * 150.0 / math.sqrt(3) * np.sin(20 * TH), 0.0)
    var = np.where(near, (3.0 * 150.0 / math.sqrt(3)) ** 2, 0.0)  # the stated variance: the error's amplitude squared
    assert not assess(Y, Y.mean(axis=0), CURVE + err, MASK, 0, 0.01).adequate
    assert assess(Y, Y.mean(axis=0), CURVE + err, MASK, 0, 0.01, model_variance=var).adequate
    assert not assess(Y, Y.mean(axis=0), CURVE + err + np.roll(err, 180), MASK, 0, 0.01, model_variance=var).adequate


def test_a_score_test_beside_a_stated_model_curve_variance_keeps_its_t_at_unit_scale():
    """A model curve whose error is large where a candidate's column is (a crank motion's error at a ramp's end, where
    the torque's slope, the offset's column, is steep): the error drawn from the variance stated beside the curve.
    The t of that candidate keeps an RMS near 1 over 300 logs with the variance in its standard error (errors in the
    variables); with the regression's pooled residual variance alone it is about 2 (the column sits where the error is)."""
    rng = np.random.default_rng(15)
    near = np.abs(TH - 4.0) < 0.3
    sd = np.where(near, 4.0 * 150.0 / math.sqrt(3), 0.0)  # four times the noise of the mean, there only
    J = CURVE[:, None] / 8000.0
    bump = Candidate("bump", "a column where the curve's error is", np.exp(-((TH - 4.0) / 0.15) ** 2)[:, None], "N m", 1.0)
    ts = {True: [], False: []}
    for _ in range(300):
        Y = strokes(rng)
        model = CURVE + rng.normal(0.0, 1.0, TH.size) * sd
        for stated in ts:
            a = assess(Y, Y.mean(axis=0), model, MASK, 1, 0.01, Suspects(J, [bump]), model_variance=sd ** 2 if stated else None)
            ts[stated].append(a.tests[0].t)
    rms = {k: math.sqrt(float(np.mean(np.square(v)))) for k, v in ts.items()}
    assert 0.88 < rms[True] < 1.12, rms
    assert rms[False] > 1.5, rms
