"""The compiled quadratic fit gives numpy's least-squares fit, to rounding."""

import numpy as np
import pytest

from trustfg.agent.motion_fit import quadratic_fit


@pytest.mark.parametrize("seed", range(20))
def test_the_fit_is_numpys_least_squares(seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(4, 40))
    times = np.unique(np.sort(rng.uniform(0.0, 0.4, k)) + rng.uniform(0.0, 5000.0))
    tau = times - times[-1]
    truth = rng.normal(size=(3, 2)) * [[5.0], [1.0], [2.0]]
    xy = truth[0] + tau[:, None] * truth[1] + tau[:, None] ** 2 * truth[2] + rng.normal(0.0, 0.002, (len(times), 2))
    design = np.stack([np.ones_like(tau), tau, tau**2], axis=1)
    coef, *_ = np.linalg.lstsq(design, xy, rcond=None)
    fit = quadratic_fit(times, xy, times[-1])
    assert fit == pytest.approx(np.array([coef[0], coef[1], 2.0 * coef[2]]), rel=1e-8, abs=1e-8)


def test_an_exact_quadratic_is_recovered():
    times = np.linspace(10.0, 10.4, 21)
    tau = times - times[-1]
    xy = np.column_stack([1.0 + 0.5 * tau - 0.75 * tau**2, -2.0 + 0.1 * tau + 1.5 * tau**2])
    fit = quadratic_fit(times, xy, times[-1])
    assert fit == pytest.approx(np.array([[1.0, -2.0], [0.5, 0.1], [-1.5, 3.0]]), abs=1e-9)
