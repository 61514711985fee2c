"""Sobol plumbing (problem, sampling, analysis, screening) on a response with known indices."""
import numpy as np
import pytest

from calibration.sensitivity import sobol as S
from press_io.errors import PressDataError
from press_model.press_data import load_press


def test_problem_has_the_28_parameters_with_reference_ranges():
    prob = S.problem(load_press())
    assert prob["num_vars"] == 28
    b = dict(zip(prob["names"], prob["bounds"]))
    assert b["eta_gear"] == [0.7, 0.99] and b["mu_r"] == [0.005, 0.05] and b["mu_s"] == [0.02, 0.2] and b["psi"] == [1.0, 1.3]
    assert b["m8"] == pytest.approx([0.7 * 30595, 1.3 * 30595])


def test_known_indices_are_recovered_and_screened():
    """Y = a + 2 b (additive, uniform inputs on [0,1]): S_a = 1/5, S_b = 4/5, c inert."""
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    X = S.sample(prob, 1024, seed=0)
    assert X.shape == (1024 * 5, 3)

    def ev(x):
        y = x[:, 0] + 2 * x[:, 1]
        return np.column_stack([y, 0.1 * x[:, 0] + x[:, 2] ** 2, y, y])

    Y = S.evaluate(ev, X, chunk=1000, progress=False)
    ind = S.analyze(prob, Y, seed=0)
    assert ind[0].ST[0] == pytest.approx(0.2, abs=0.03) and ind[0].ST[1] == pytest.approx(0.8, abs=0.03)
    assert abs(ind[0].ST[2]) < 0.01
    # c matters only through the second (Y_PR) column, where it dominates; order is by the larger S_T
    assert S.key_parameters(ind) == ["c", "b", "a"]
    assert S.key_parameters(ind, threshold=0.5) == ["c", "b"]


@pytest.mark.parametrize("second_order", [False, True])
@pytest.mark.parametrize("n, seed", [(2, 0), (256, 7), (2048, 1)])
def test_design_is_salibs_sobol_sample_to_the_bit(n, seed, second_order):
    """The design is built with numpy, not SALib's loop: the same matrix, byte for byte, for the reference press's
    28 parameters (and second order, whose rows also swap B's columns for A's)."""
    from SALib.sample import sobol

    prob = S.problem(load_press())
    ours = S.sample(dict(prob), n, seed, second_order)
    salib = sobol.sample(dict(prob), n, calc_second_order=second_order, seed=seed)
    assert ours.shape == salib.shape == (n * ((2 if second_order else 1) * 28 + 2), 28)
    assert ours.tobytes() == salib.tobytes()


def test_n_must_be_a_power_of_two():
    with pytest.raises(PressDataError, match="power of two"):
        S.sample(S.problem(load_press()), 1000, seed=0)


@pytest.mark.parametrize("seed", [0, 7])
def test_bootstrap_intervals_repeat_for_the_same_seed(seed):
    """SALib skips seeding for seed 0; our analysis must still give the same intervals twice."""
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    X = S.sample(prob, 256, seed=seed)
    y = X[:, 0] + 2 * X[:, 1] ** 2 + 0.3 * X[:, 2]
    Y = np.column_stack([y, y, y, y])
    a, b = S.analyze(prob, Y, seed=seed), S.analyze(prob, Y, seed=seed)
    assert all(np.array_equal(i.ST_conf, j.ST_conf) and np.array_equal(i.S1_conf, j.S1_conf) for i, j in zip(a, b))


def test_analysis_in_two_processes_gives_the_same_indices():
    """The four analyses may run in forked processes: each has its own seeded bootstrap, so the result is the same."""
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    X = S.sample(prob, 256, seed=1)
    Y = np.column_stack([X[:, 0] + k * X[:, 1] ** 2 + 0.3 * X[:, 2] for k in range(4)])
    a, b = S.analyze(prob, Y, seed=1, workers=1), S.analyze(prob, Y, seed=1, workers=2)
    for i, j in zip(a, b):
        assert i.response == j.response
        for f in ("S1", "S1_conf", "ST", "ST_conf"):
            assert np.array_equal(getattr(i, f), getattr(j, f)), f


@pytest.mark.usefixtures("pyplot_imported")  # the SALib process forked with matplotlib (fixtures_suitecal.py)
def test_the_salib_process_samples_and_analyses_as_this_one_does():
    """The sensitivity command samples and analyses in a process forked at its start: the same design and indices."""
    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    with S.salib_workers() as workers:
        if workers is None:
            pytest.skip("this system cannot fork")
        X = S.sample_later(prob, 512, 3, workers=workers).result()
        assert np.array_equal(X, S.sample(prob, 512, seed=3))
        Y = np.column_stack([X[:, 0] + k * X[:, 1] ** 2 + 0.3 * X[:, 2] for k in range(4)])
        there = S.analyze(prob, Y, seed=3, workers=2, pool=workers)
        with pytest.raises(PressDataError, match="power of two"):  # refused here, before it reaches the process
            S.sample_later(prob, 500, 3, workers=workers)
    here = S.analyze(prob, Y, seed=3, workers=1)
    for i, j in zip(here, there):
        for f in ("S1", "S1_conf", "ST", "ST_conf"):
            assert np.array_equal(getattr(i, f), getattr(j, f)), f


@pytest.mark.usefixtures("pyplot_imported")  # the SALib process forked with matplotlib (fixtures_suitecal.py)
def test_the_salib_process_draws_the_figure_this_one_draws(tmp_path):
    """The sensitivity command's figure is drawn in its SALib process: the same bytes as drawn here."""
    from press_model.plots import save_later

    prob = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0, 1]] * 3}
    X = S.sample(prob, 256, seed=2)
    indices = S.analyze(prob, np.column_stack([X[:, 0] + k * X[:, 1] ** 2 + 0.3 * X[:, 2] for k in range(4)]), seed=2, workers=1)
    with S.salib_workers() as workers:
        if workers is None:
            pytest.skip("this system cannot fork")
        save_later(workers, S.figure, (indices, "toy"), tmp_path / "there.png").result()
    save_later(None, S.figure, (indices, "toy"), tmp_path / "here.png").result()
    assert (tmp_path / "there.png").read_bytes() == (tmp_path / "here.png").read_bytes()
