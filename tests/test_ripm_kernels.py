"""The RIPM's compiled iteration kernels give the NumPy expressions they replace, bit for bit."""

import numpy as np
import pytest
import scipy.sparse as sp

from mbplan.solvers.ripm import kernels as k
from mbplan.solvers.ripm.iterate import amax, finite, transpose_times

SIZES = [0, 1, 7, 8, 9, 127, 128, 129, 300, 1024, 1031, 4099]


def _vec(rng, n, positive=False):
    """Entries over 16 orders of magnitude: a different summation order shows."""
    v = rng.standard_normal(n) * 10.0 ** rng.integers(-8, 8, n)
    return np.abs(v) + 1e-3 if positive else v


@pytest.mark.parametrize("n", SIZES)
def test_sums_are_numpys_pairwise_sums(n):
    rng = np.random.default_rng(n)
    a, b = _vec(rng, n), _vec(rng, n, positive=True)
    assert k.pairwise_sum(a) == np.sum(a)
    assert k.abs_sum(a) == np.sum(np.abs(a))
    assert k.ratio_sum(a, b) == np.sum(a / b)
    assert amax(a) == (np.abs(a).max() if n else 0.0)
    assert np.signbit(k.pairwise_sum(-np.zeros(n))) == np.signbit(np.sum(-np.zeros(n)))


def test_nan_propagates_through_the_norms():
    v = np.array([1.0, np.nan, 3.0])
    assert np.isnan(amax(v))
    assert np.isnan(k.complementarity_error(v, np.ones(3), 0.0))
    assert not finite(v) and not finite(np.array([np.inf])) and not finite(np.nan)
    assert finite(np.ones(3), 2.0, np.zeros((2, 2)), np.zeros(0, np.int64))
    long = np.ones(20000)  # NumPy's check above 8192 entries
    assert finite(long)
    long[-1] = np.inf
    assert not finite(long) and not finite(long[-100:])


@pytest.mark.parametrize("n", [0, 5, 200])
def test_step_and_safeguard_kernels_match_numpy(n):
    rng = np.random.default_rng(7 + n)
    s, z = _vec(rng, n, positive=True), _vec(rng, n, positive=True)
    dz, ds = _vec(rng, n), _vec(rng, n)
    mu, tau, kappa = 0.1, 0.99, 1e10
    none = np.zeros(0)
    assert np.array_equal(k.slack_step(s, z, dz, mu, none), -s + mu / z - s * dz / z)
    shift = _vec(rng, n)
    want = -s + mu / z - s * dz / z
    want -= shift / z
    assert np.array_equal(k.slack_step(s, z, dz, mu, shift), want)
    neg = ds < 0
    ftb = float(min(1.0, (-tau * s[neg] / ds[neg]).min())) if neg.any() else 1.0
    assert k.frac_to_boundary(s, ds, tau) == ftb
    assert k.frac_to_boundary(s, np.abs(ds), tau) == 1.0
    clipped = np.clip(z + 0.3 * dz, mu / (kappa * s), kappa * mu / s)
    assert np.array_equal(k.safeguarded_duals(z, dz, 0.3, s, mu, kappa), clipped)
    assert k.complementarity_error(s, z, mu) == (np.abs(s * z - mu).max() if n else 0.0)


@pytest.mark.parametrize("n", [1, 5, 200, 1031])
def test_mehrotra_kernels_match_numpy(n):
    """The probing oracle's averages and the corrector's shift are the NumPy expressions of
    the barrier strategy and the Newton step they replace."""
    rng = np.random.default_rng(11 + n)
    s, z = _vec(rng, n, positive=True), _vec(rng, n, positive=True)
    ds, dz = _vec(rng, n), _vec(rng, n)
    tau = 0.995
    assert k.mean_product(s, z) == float(np.mean(s * z))
    a_p, a_d = k.frac_to_boundary(s, ds, tau), k.frac_to_boundary(z, dz, tau)
    mu_aff = float(np.mean((s + a_p * ds) * (z + a_d * dz)))
    assert k.affine_complementarity(s, ds, z, dz, tau) == mu_aff
    shift, reach = k.corrector_shift(s, ds, z, dz, tau)
    assert np.array_equal(shift, (a_p * a_d) * (ds * dz)) and reach == min(a_p, a_d)


@pytest.mark.parametrize(("me", "mi"), [(30, 0), (0, 20), (30, 20)])
def test_newton_system_kernels_match_numpy(me, mi):
    rng = np.random.default_rng(me + mi)
    n = 40
    s, z = _vec(rng, mi, positive=True), _vec(rng, mi, positive=True)
    r_d, c = _vec(rng, n), _vec(rng, me + mi)
    mu, dw, dc = 0.01, 1e-4, 1e-8
    lower = -c
    lower[me:] += s - mu / z
    rhs = np.empty(n + me + mi)
    k.newton_rhs(r_d, c, me, s, z, mu, np.zeros(0), rhs)
    assert np.array_equal(rhs, np.concatenate([-r_d, lower]))
    shift = _vec(rng, mi)
    k.newton_rhs(r_d, c, me, s, z, mu, shift, rhs)
    want = np.concatenate([-r_d, lower])
    want[n + me :] += shift / z
    assert np.array_equal(rhs, want)
    dual = np.full(me + mi, -dc)
    dual[me:] -= s / z
    diagonal = np.empty(n + me + mi)
    k.newton_diagonal(n, me, dw, dc, s, z, diagonal)
    assert np.array_equal(diagonal, np.concatenate([np.full(n, dw), dual]))


@pytest.mark.parametrize("sigma", [1.0, 0.0, 0.5])
def test_residuals_match_the_scipy_expressions(sigma):
    rng = np.random.default_rng(3)
    n, me, mi = 50, 30, 20
    a_e = sp.random(me, n, density=0.2, format="csr", random_state=rng)
    a_i = sp.random(mi, n, density=0.2, format="csr", random_state=rng)
    grad, y, z = _vec(rng, n), _vec(rng, me), _vec(rng, mi, positive=True)
    h, g, s = _vec(rng, me), _vec(rng, mi), _vec(rng, mi, positive=True)
    r_d, r_c = np.empty(n), np.empty(me + mi)
    arrays = (a_e.indptr, a_e.indices, a_e.data, y, a_i.indptr, a_i.indices, a_i.data, z)
    inf_du, inf_pr = k.residuals(grad, sigma, *arrays, h, g, s, r_d, r_c)
    expected_d = (grad if sigma == 1.0 else sigma * grad) + a_e.T @ y + a_i.T @ z
    expected_c = np.concatenate([h, g + s])
    assert np.array_equal(r_d, expected_d) and np.array_equal(r_c, expected_c)
    assert inf_du == np.abs(expected_d).max() and inf_pr == np.abs(expected_c).max()
    c = np.empty(me + mi)
    assert k.constraint_values(h, g, s, c) == np.sum(np.abs(expected_c))
    assert np.array_equal(c, expected_c)


def test_empty_blocks_of_any_dtype():
    """An empty Jacobian block (integer data from ``np.bincount`` of nothing) is a zero product."""
    empty = sp.csr_matrix(
        (np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(1, np.int32)), shape=(0, 5)
    )
    assert empty.dtype == np.int64
    assert np.array_equal(transpose_times(empty, np.zeros(0)), np.zeros(5))


def test_kernels_divide_by_zero_as_numpy_does():
    """A zero slack gives infinite bounds (NumPy's semantics), not a ZeroDivisionError from
    inside a compiled kernel: the solver's finiteness checks then report a numerical error."""
    s = np.array([0.0, 1.0])
    with np.errstate(divide="ignore"):
        want = np.minimum(np.maximum(np.ones(2) + 0.5, 0.1 / (10.0 * s)), 10.0 * 0.1 / s)
        got = k.safeguarded_duals(np.ones(2), np.ones(2), 0.5, s, 0.1, 10.0)
    assert np.isinf(got[0])
    np.testing.assert_array_equal(got, want)
