"""The Sobol analysis of the first and total order (calibration/sensitivity/sobol.py ``_first_and_total``) gives SALib's
``sobol.analyze`` numbers to the bit: it calls SALib's own estimators, with the bootstrap resamples gathered once."""
import numpy as np
import pytest
from SALib.analyze import sobol as salib

from calibration.sensitivity import sobol as S
from press_model.press_data import load_press


def _responses(X: np.ndarray) -> np.ndarray:
    """Four responses of unequal shape over the parameters (scaled to [0, 1]): additive, interacting, a dominant one."""
    u = (X - X.min(axis=0)) / np.ptp(X, axis=0)
    return np.column_stack([u[:, 0] + 2 * u[:, 1] ** 2 + 0.1 * u[:, 2:].sum(axis=1),
                            u[:, 3] * u[:, 4] + np.sin(3 * u[:, 5]),
                            np.exp(u[:, 6]) + 1e-3 * u[:, 7],
                            1e4 * (u[:, 8] - 0.5) ** 3 + u[:, 9] * u[:, 10] * u[:, 11]])


@pytest.mark.parametrize("n, seed", [(64, 0), (256, 7)])
def test_first_and_total_order_are_salibs_to_the_bit(n, seed):
    prob = S.problem(load_press())
    X = S.sample(prob, n, seed)
    Y = _responses(X)
    ours = S.analyze(prob, Y, seed, workers=1)
    boot_seed = int(np.random.SeedSequence(seed).generate_state(1)[0]) or 1
    for k, ind in enumerate(ours):
        theirs = salib.analyze(dict(prob), np.ascontiguousarray(Y[:, k]), calc_second_order=False, num_resamples=100,
                               conf_level=0.95, seed=boot_seed)
        for f in ("S1", "S1_conf", "ST", "ST_conf"):
            assert getattr(ind, f).tobytes() == np.asarray(theirs[f], dtype=float).tobytes(), (ind.response, f)


def test_a_resample_without_spread_gives_zero_intervals_as_salib_does():
    """A response that varies in the AB rows alone: every resample of A and B is constant, so SALib sets the intervals
    to zero (and warns); so does ours."""
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    y = np.zeros(8 * 5)
    y[1::5] = np.arange(8.0)  # the rows of A with column a from B
    with pytest.warns(UserWarning):
        ours = S._first_and_total(prob, y, 20, 5)
    with pytest.warns(UserWarning):
        theirs = salib.analyze(prob, y, calc_second_order=False, num_resamples=20, seed=5)
    for f in ("S1", "S1_conf", "ST", "ST_conf"):
        assert ours[f].tobytes() == np.asarray(theirs[f], dtype=float).tobytes(), f
    assert not ours["S1_conf"].any() and not ours["ST_conf"].any()


def test_a_salib_release_not_checked_runs_salibs_own_analyze(monkeypatch):
    """On a SALib release the repeated steps were not checked on, SALib's ``sobol.analyze`` itself gives the numbers."""
    calls = []
    monkeypatch.setattr(S, "salib_release", lambda: (99, 0))
    monkeypatch.setattr(salib, "analyze", lambda *a, **k: calls.append(k) or {f: np.zeros(3) for f in ("S1", "S1_conf", "ST", "ST_conf")})
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    S._first_and_total(prob, np.arange(40.0), 20, 5)
    assert calls and calls[0]["seed"] == 5
