"""The ant colony optimiser (calibration.aco): convergence, bounds, bookkeeping, determinism, settings.

All runs use the paper's settings (Section 4.2) from the TOML table below, which is the table a job file
carries as [calibration.aco]. Tolerances on the optimum are fractions of each parameter's range: 1e-4 of
the range is five times finer than the finest value the paper reports for its calibrated parameters
(m_s = 32,940 kg, to 10 kg on a 19,000 kg range = 5e-4), so an optimiser that meets it resolves the
calibration better than the paper's tables do.
"""
import dataclasses
import tomllib

import numpy as np
import pytest

from calibration.identification.aco import AcoResult, AcoSettings, minimize_aco
from press_io.errors import PressDataError

PAPER_TOML = """
[calibration.aco]
ants = 50                  # ants per iteration (paper 4.2); the colony is one batch evaluation
iterations = 100           # iterations (paper 4.2); always all run: nfev = archive_size + ants * iterations
elite_coefficient = 2.0    # elitist ants (paper 4.2): best-so-far trail gets e * Q per iteration
pheromone_weight = 1.0     # alpha, trail exponent in the guide probability (paper 4.2)
heuristic_weight = 2.0     # beta, exponent of eta = 1 / normalised cost (paper 4.2)
evaporation_min = 0.1      # rho while the best-so-far improves, 1/iteration (paper 4.2: [0.1, 0.9])
evaporation_max = 0.9      # rho after stagnation_window iterations without improvement, 1/iteration (paper 4.2)
pheromone_intensity = 100.0  # Q, pheromone per deposit of normalised cost 1 (paper 4.2); cancels in p
archive_size = 50          # solutions kept as the pheromone table (chosen: Socha & Dorigo 2008)
spread = 0.85              # kernel width / archive mean distance, xi (chosen: Socha & Dorigo 2008)
stagnation_window = 5      # iterations without improvement for rho to reach evaporation_max (chosen)
kernel = "mixed"           # half the ants rotated (archive principal directions, ACO_R), half per parameter
trail_ratio = 10.0         # MAX-MIN bounds tau_max / tau_min: guide choice cannot collapse onto one point
polish_evaluations = 450   # budget of the final polish (used only when minimize_aco is given a polish)
"""
PAPER_TABLE = tomllib.loads(PAPER_TOML)["calibration"]["aco"]
PAPER = AcoSettings.from_mapping(PAPER_TABLE, "test")
SEEDS = (11, 22, 33, 44, 55)

# six bounds of very different magnitudes (the calibrated parameters' kind: efficiency, psi, mu_r, m_s, J, mu_s)
LOW6 = np.array([0.7, 1.0, 0.005, 21000.0, 38.0, 0.02])
HIGH6 = np.array([0.99, 1.3, 0.05, 40000.0, 71.0, 0.2])
TRUE6 = np.array([0.842, 1.06, 0.012, 32940.0, 60.6, 0.085])
CURV6 = np.array([1.0, 10.0, 100.0, 1000.0, 3.0, 30.0])  # curvature ratio 1000 even after scaling to the range


def quad6(X):
    Z = (X - TRUE6) / (HIGH6 - LOW6)
    return (CURV6 * Z**2).sum(axis=1)


def rastrigin(X):
    return 10.0 * X.shape[1] + (X**2 - 10.0 * np.cos(2.0 * np.pi * X)).sum(axis=1)


class Recorder:
    """Wraps an objective; keeps every X it was given."""

    def __init__(self, f):
        self.f, self.calls = f, []

    def __call__(self, X):
        self.calls.append(np.array(X, copy=True))
        return self.f(X)

    @property
    def rows(self):
        return np.concatenate(self.calls)


def test_paper_table_reads_back():
    assert PAPER == AcoSettings(**PAPER_TABLE)
    assert (PAPER.ants, PAPER.iterations, PAPER.elite_coefficient, PAPER.pheromone_weight, PAPER.heuristic_weight,
            PAPER.evaporation_min, PAPER.evaporation_max, PAPER.pheromone_intensity) == (50, 100, 2.0, 1.0, 2.0, 0.1, 0.9, 100.0)


def test_shifted_sphere():
    low, high = np.array([-5.0, -5.0, -5.0]), np.array([10.0, 10.0, 10.0])
    centre = np.array([1.3, -2.2, 4.0])
    for seed in SEEDS[:2]:
        res = minimize_aco(lambda X: ((X - centre) ** 2).sum(axis=1), low, high, PAPER, seed)
        assert np.all(np.abs(res.x - centre) <= 1e-4 * (high - low))
        assert res.fun == pytest.approx(((res.x - centre) ** 2).sum(), abs=0.0)


def test_badly_scaled_quadratic_with_bounds_of_different_magnitudes():
    for seed in SEEDS:
        res = minimize_aco(quad6, LOW6, HIGH6, PAPER, seed)
        assert np.all(np.abs(res.x - TRUE6) <= 1e-4 * (HIGH6 - LOW6)), (seed, (res.x - TRUE6) / (HIGH6 - LOW6))


def test_beats_random_search_on_rastrigin():
    """Same number of evaluations; the median over seeds, since either can be lucky once."""
    low, high = np.full(2, -5.12), np.full(2, 5.12)
    aco, rnd = [], []
    for seed in SEEDS:
        res = minimize_aco(rastrigin, low, high, PAPER, seed)
        aco.append(res.fun)
        rng = np.random.default_rng(seed)
        rnd.append(rastrigin(low + (high - low) * rng.random((res.nfev, 2))).min())
    assert np.median(aco) < np.median(rnd)
    assert np.median(aco) < 1e-6  # 2-D Rastrigin's global minimum is 0; the next local minima are at ~0.995


def test_optimum_on_bounds_and_bounds_never_violated():
    # the unconstrained minimum lies outside the box in three dimensions: below low, above high, at low
    target = TRUE6.copy()
    target[0] = LOW6[0] - 0.1
    target[3] = HIGH6[3] + 5000.0
    target[1] = LOW6[1]
    rec = Recorder(lambda X: (CURV6 * ((X - target) / (HIGH6 - LOW6)) ** 2).sum(axis=1))
    res = minimize_aco(rec, LOW6, HIGH6, PAPER, 7)
    rows = rec.rows
    assert np.all(rows >= LOW6) and np.all(rows <= HIGH6)
    expect = np.clip(target, LOW6, HIGH6)
    assert np.all(np.abs(res.x - expect) <= 1e-4 * (HIGH6 - LOW6))


def test_determinism_and_seed_dependence():
    r1 = minimize_aco(quad6, LOW6, HIGH6, PAPER, 3)
    r2 = minimize_aco(quad6, LOW6, HIGH6, PAPER, 3)
    assert np.array_equal(r1.x, r2.x) and r1.fun == r2.fun
    assert np.array_equal(r1.history_best, r2.history_best) and np.array_equal(r1.history_rho, r2.history_rho)
    a, b = Recorder(quad6), Recorder(quad6)
    minimize_aco(a, LOW6, HIGH6, PAPER, 3)
    minimize_aco(b, LOW6, HIGH6, PAPER, 4)
    assert not np.array_equal(a.calls[0], b.calls[0])
    assert not np.array_equal(a.rows, b.rows)


def test_bookkeeping():
    rec = Recorder(quad6)
    seen = []
    res = minimize_aco(rec, LOW6, HIGH6, PAPER, 5, progress=lambda it, f, rho: seen.append((it, f, rho)))
    assert isinstance(res, AcoResult)
    # one call for the initial archive, then one call of `ants` rows per iteration
    assert [len(c) for c in rec.calls] == [PAPER.archive_size] + [PAPER.ants] * PAPER.iterations
    assert res.nfev == len(rec.rows) == PAPER.archive_size + PAPER.ants * PAPER.iterations
    assert res.nit == PAPER.iterations
    assert [s[0] for s in seen] == list(range(1, PAPER.iterations + 1))
    assert res.history_best.shape == (res.nit + 1,) and res.history_rho.shape == (res.nit,)
    assert np.all(np.diff(res.history_best) <= 0.0)
    assert [s[1] for s in seen] == list(res.history_best[1:]) and [s[2] for s in seen] == list(res.history_rho)
    assert res.history_best[-1] == res.fun
    # the reported best is the best row ever evaluated, and its value is fun(x)
    assert res.fun == quad6(rec.rows).min() == quad6(res.x[None])[0]
    assert np.all((res.history_rho >= PAPER.evaporation_min) & (res.history_rho <= PAPER.evaporation_max))
    assert res.history_rho[0] == PAPER.evaporation_min
    assert res.settings == PAPER and res.seed == 5 and res.time_s > 0.0
    assert res.pheromone.shape == (PAPER.archive_size,) and np.all(res.pheromone > 0.0)


def test_adaptive_evaporation_follows_stagnation():
    """The documented rule, replayed from the best-so-far history."""
    res = minimize_aco(rastrigin, np.full(2, -5.12), np.full(2, 5.12), PAPER, 9)
    s, stall = PAPER, 0
    for it in range(res.nit):
        expect = s.evaporation_min + (s.evaporation_max - s.evaporation_min) * min(1.0, stall / s.stagnation_window)
        assert res.history_rho[it] == pytest.approx(expect, rel=1e-12)
        stall = 0 if res.history_best[it + 1] < res.history_best[it] else stall + 1
    assert res.history_rho.max() == s.evaporation_max  # the run stagnates once at its optimum


def test_x0_joins_the_initial_archive():
    rec = Recorder(quad6)
    res = minimize_aco(rec, LOW6, HIGH6, PAPER, 1, x0=TRUE6)
    assert any(np.array_equal(row, TRUE6) for row in rec.calls[0])
    assert res.history_best[0] == 0.0 and np.array_equal(res.x, TRUE6)  # nothing beats an exact zero


def test_pheromone_intensity_cancels_but_trails_matter():
    """Q scales every trail alike (documented): Q = 1 and Q = 128 give identical runs (a power of two, so the
    scaling is exact in floating point), while switching the trails off (alpha = 0) changes the path."""
    low, high = np.full(2, -5.12), np.full(2, 5.12)
    runs = {q: minimize_aco(rastrigin, low, high, dataclasses.replace(PAPER, pheromone_intensity=q), 2) for q in (1.0, 128.0)}
    assert np.array_equal(runs[1.0].history_best, runs[128.0].history_best)
    assert np.array_equal(runs[1.0].x, runs[128.0].x)
    assert np.allclose(runs[128.0].pheromone, 128.0 * runs[1.0].pheromone, rtol=1e-12, atol=0.0)
    no_trail = minimize_aco(rastrigin, low, high, dataclasses.replace(PAPER, pheromone_weight=0.0), 2)
    assert not np.array_equal(no_trail.history_best, runs[1.0].history_best)


def test_nan_rows_are_never_the_answer():
    # NaN in a ball around the minimum of the finite part, and in the half-space x[0] < its optimum value

    def f(X):
        out = quad6(X)
        z = (X - TRUE6) / (HIGH6 - LOW6)
        out[(np.sqrt((z**2).sum(axis=1)) < 0.05) | (z[:, 0] < 0.0)] = np.nan
        return out

    rec = Recorder(f)
    res = minimize_aco(rec, LOW6, HIGH6, PAPER, 8)
    assert np.isfinite(res.fun) and res.fun == f(res.x[None])[0]
    vals = f(rec.rows)
    assert np.isnan(vals).any()  # the NaN region was visited, so the test means something
    assert res.fun == np.nanmin(vals)
    # a worst-case objective: no finite value at all still returns, and says so
    none = minimize_aco(lambda X: np.full(len(X), np.nan), LOW6, HIGH6, PAPER, 8)
    assert none.fun == np.inf and "no finite" in none.message
    assert np.all(none.x >= LOW6) and np.all(none.x <= HIGH6)


@pytest.mark.parametrize(
    "key, value",
    [
        ("ants", 1),
        ("ants", 2.5),
        ("iterations", 0),
        ("elite_coefficient", -1.0),
        ("pheromone_weight", -1.0),
        ("heuristic_weight", -0.5),
        ("evaporation_min", 0.0),
        ("evaporation_min", 1.0),
        ("evaporation_max", 1.0),
        ("evaporation_max", 0.05),  # below evaporation_min = 0.1
        ("pheromone_intensity", 0.0),
        ("archive_size", 1),
        ("spread", 0.0),
        ("stagnation_window", 0),
        ("spread", float("nan")),
        ("ants", True),
    ],
)
def test_invalid_setting_names_its_key(key, value):
    table = {**PAPER_TABLE, key: value}
    with pytest.raises(PressDataError) as err:
        AcoSettings.from_mapping(table, "job.toml")
    assert err.value.field == f"aco.{key}" and err.value.source == "job.toml"


def test_min_above_max_names_evaporation_max():
    with pytest.raises(PressDataError) as err:
        AcoSettings.from_mapping({**PAPER_TABLE, "evaporation_min": 0.95}, "job.toml")
    assert err.value.field == "aco.evaporation_max" and "evaporation_min" in str(err.value)


def test_unknown_keys_are_refused_and_missing_ones_take_the_papers_settings():
    with pytest.raises(PressDataError) as err:
        AcoSettings.from_mapping({**PAPER_TABLE, "antz": 50}, "job.toml")
    assert err.value.field == "aco.antz" and "did you mean 'ants'" in str(err.value)
    table = dict(PAPER_TABLE)
    del table["spread"]
    assert AcoSettings.from_mapping(table, "job.toml") == PAPER  # the default spread is the paper table's 0.85
    assert AcoSettings.from_mapping({}, "job.toml") == PAPER
    with pytest.raises(PressDataError) as err:
        AcoSettings.from_mapping({"evaporation_min": 0.5, "evaporation_max": 0.4}, "job.toml")
    assert err.value.field == "aco.evaporation_max"


def test_minimize_checks_its_inputs():
    with pytest.raises(PressDataError) as err:
        minimize_aco(quad6, LOW6, HIGH6, dataclasses.replace(PAPER, ants=1), 0)
    assert err.value.field == "aco.ants"
    with pytest.raises(PressDataError) as err:
        minimize_aco(quad6, HIGH6, LOW6, PAPER, 0)
    assert err.value.field == "low/high"
    with pytest.raises(PressDataError) as err:
        minimize_aco(quad6, LOW6, HIGH6, PAPER, 0, x0=HIGH6 * 1.01)
    assert err.value.field == "x0"
    with pytest.raises(PressDataError) as err:
        minimize_aco(quad6, LOW6, HIGH6, PAPER, 1.5)
    assert err.value.field == "seed"


# --- convergence against a known minimum: a slanted narrow valley with Eq. 28's kink ------------------------
# f = w A / a0 + (1 - w) |B| / b0 with A = sqrt(a0^2 + z^T H z), B = g . z, z = (x - X_STAR) / range. A is smallest
# (= a0) only at z = 0 and |B| too, so the minimum is x = X_STAR with f = w exactly. H has a valley slanted across
# the first and third parameters (as eta_gear and mu_r in Eq. 28), 1000 times narrower across than along it, and
# b0 is small, so the kink B = 0 dominates as Eq. 28's peak term does when Y_PR,0 is small.
X_STAR = np.array([0.861, 1.19, 0.031, 26500.0, 45.0, 0.131])
_V = np.linalg.qr(np.array([[1.0, 0, 0.9, 0, 0, 0], [0, 1, 0, 0.3, 0, 0], [-0.9, 0, 1, 0, 0, 0],
                            [0, 0, 0, 1, 0.2, 0], [0, 0.1, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]).T)[0]
_H = _V @ np.diag([1.0, 40.0, 1000.0, 60.0, 20.0, 30.0]) @ _V.T  # along the valley (first column) 1, across 1000
_G = np.array([0.6, 0.2, 0.5, 0.3, 0.2, 0.4])
A0, B0, W = 0.05, 0.01, 0.3


def valley_parts(X):
    Z = (X - X_STAR) / (HIGH6 - LOW6)
    return np.sqrt(A0**2 + np.einsum("bi,ij,bj->b", Z, _H, Z)), Z @ _G


def valley(X):
    A, B = valley_parts(X)
    return W * A / A0 + (1.0 - W) * np.abs(B) / B0


def valley_polish(x, fx, budget):
    from calibration.identification.polish import polish_two_part

    r = polish_two_part(valley_parts, x, (LOW6, HIGH6), (W, A0, B0), budget, f0=fx)
    return r.x, r.fun, r.nfev, r.message


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_reaches_the_known_minimum_of_a_slanted_kinked_valley_within_the_paper_budget(seed):
    rec = Recorder(valley)
    res = minimize_aco(rec, LOW6, HIGH6, PAPER, seed, x0=0.5 * (LOW6 + HIGH6), polish=valley_polish)
    assert res.nfev <= 5500 and len(rec.rows) + res.polish_nfev == res.nfev
    assert res.fun <= 1.01 * W  # within 1 % of the analytic minimum f = w
    assert res.fun == pytest.approx(valley(res.x[None])[0], rel=1e-12)
    assert np.all(np.abs(res.x - X_STAR) <= 0.01 * (HIGH6 - LOW6))


def test_polish_never_returns_worse_and_keeps_its_budget():
    from calibration.identification.polish import polish_two_part

    counted = []

    def parts(X):
        counted.append(len(X))
        return valley_parts(X)

    x0 = X_STAR + 0.2 * (HIGH6 - LOW6) * np.array([1, -1, 0.5, 0.3, -0.4, 0.2])
    for budget in (1, 13, 40, 400):
        counted.clear()
        r = polish_two_part(parts, x0, (LOW6, HIGH6), (W, A0, B0), budget)
        assert sum(counted) == r.nfev <= budget
        assert r.fun <= valley(x0[None])[0] and r.fun == pytest.approx(valley(r.x[None])[0], rel=1e-12)
    # with room, from far away on its own, the polish finds the exact minimum (the problem is convex)
    r = polish_two_part(valley_parts, x0, (LOW6, HIGH6), (W, A0, B0), 2000)
    assert r.fun == pytest.approx(W, rel=1e-6)


def test_trail_bounds_keep_several_guides():
    """On a 6-D Rastrigin (many local minima, long stagnation) the elitist deposits without MAX-MIN bounds make
    one or two archive points almost the only guides; with them (trail_ratio 10) guide choice stays spread
    over several points in every iteration. Effective number of guides: 1 / sum p_l^2."""
    def rastrigin6(X):
        return rastrigin((X - LOW6) / (HIGH6 - LOW6) * 10.24 - 5.12)

    for seed in (4, 5):
        free = minimize_aco(rastrigin6, LOW6, HIGH6, dataclasses.replace(PAPER, trail_ratio=1e12), seed)
        bounded = minimize_aco(rastrigin6, LOW6, HIGH6, PAPER, seed)
        assert np.median(free.history_guides[20:]) < 4.0
        assert bounded.history_guides[20:].min() > 4.5
        assert bounded.pheromone.max() / bounded.pheromone.min() <= PAPER.trail_ratio * (1 + 1e-12)
