"""F_env of Sec. 3.2: Gaussian knots every second, linear in between."""

import numpy as np
import pytest

from pd_core.config import DISTURBANCE
from pd_core.disturbance import force_at, sample_knots


def test_knot_statistics_match_sigma_100n():
    knots = np.concatenate([sample_knots(np.random.default_rng(s), 150.0) for s in range(200)])
    assert knots.shape[1] == 3
    assert knots.size > 80_000
    assert np.std(knots) == pytest.approx(DISTURBANCE.sigma_n, rel=0.05)
    assert abs(np.mean(knots)) < 3.0  # 5 sigma of the mean's standard error (~0.35 N)


def test_linear_interpolation_between_one_second_knots():
    knots = sample_knots(np.random.default_rng(3), 10.0)
    for t in (0.0, 1.0, 4.0):  # exactly the knots at whole seconds
        np.testing.assert_array_equal(force_at(knots, t), knots[int(t)])
    for t in (0.1, 2.3, 7.9):
        i, f = int(t), t - int(t)
        np.testing.assert_allclose(
            force_at(knots, t), (1 - f) * knots[i] + f * knots[i + 1], atol=1e-12
        )


def test_batched_interpolation_matches_single():
    rng = np.random.default_rng(1)
    knots = np.stack([sample_knots(rng, 20.0) for _ in range(5)])
    t = np.array([0.1, 3.5, 7.3, 12.0, 19.9])
    out = force_at(knots, t)
    for i in range(5):
        np.testing.assert_allclose(out[i], force_at(knots[i], t[i]))


def test_same_seed_same_disturbance():
    a = sample_knots(np.random.default_rng(42), 30.0)
    b = sample_knots(np.random.default_rng(42), 30.0)
    np.testing.assert_array_equal(a, b)
