"""The QP baseline (Sec. 5.2.2) against qpsolvers, the library whose call it replaces: the same
weights bit for bit on random and degenerate problems (qpsolvers' own path:
:func:`mcbench.combine.simplex_solvers.qp.qp_simplex_weights_through_qpsolvers`)."""

import numpy as np
import pytest

from mcbench.combine.simplex_solvers.qp import qp_simplex_weights, qp_simplex_weights_through_qpsolvers


def _problems(rng, count, n, d):
    points = rng.lognormal(size=(count, n, d)) * rng.choice([1e-4, 1.0, 1e3], size=(count, 1, 1))
    targets = points.mean(axis=1) + 0.3 * rng.standard_normal((count, d)) * points.std(axis=1)
    points[: count // 8, 1] = points[: count // 8, 0]          # two identical denoisers
    targets[count // 8: count // 4] = 0.0                       # a black target
    points[count // 4: count // 4 + 3] = 0.0                    # every denoiser black
    return points, targets


@pytest.mark.parametrize("n, d", [(2, 2), (4, 2), (5, 6), (8, 2)])
def test_the_weights_equal_qpsolvers_bit_for_bit(n, d):
    points, targets = _problems(np.random.default_rng(n * 10 + d), 400, n, d)
    ours = qp_simplex_weights(points, targets)
    assert np.array_equal(ours, qp_simplex_weights_through_qpsolvers(points, targets))
    assert np.all(ours >= 0.0) and np.allclose(ours.sum(axis=1), 1.0, rtol=0, atol=1e-12)


def test_one_denoiser_gets_all_the_weight():
    assert np.array_equal(qp_simplex_weights(np.ones((3, 1, 2)), np.zeros((3, 2))), np.ones((3, 1)))
