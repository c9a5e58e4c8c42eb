"""The KKT solve path: the compiled residual against SciPy, the refined solve against dense
linear algebra (8-column front kernels, near-singular systems whose refinement must report
failure) and the assembly scatters."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_linear_solver import _dense, _kkt_blocks

from mbplan.solvers.kkt.ldl.solve import _residual_into
from mbplan.solvers.kkt.scatter import same_arrays
from mbplan.solvers.kkt.system import KKTSystem


def _system(seed, n=240, me=108, mi=30, band=24, shift=1e-3):
    rng = np.random.default_rng(seed)
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, 0.02, band)
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(hess, jac_e, jac_i)
    diag = np.concatenate([np.full(n, shift), -rng.uniform(0.1, 1, me), -rng.random(mi)])
    return kkt, _dense(hess, jac_e, jac_i, diag), diag, rng


def test_residual_kernel_matches_scipy_on_the_full_matrix():
    kkt, k_dense, diag, rng = _system(0)
    kkt.factorize(diag, static_reg=1e-9)
    b, x = rng.normal(size=kkt.dim), rng.normal(size=kkt.dim)
    r = np.empty(kkt.dim)
    pat = kkt._pattern
    nrm_r, nrm_x = _residual_into(pat.full_indptr, pat.full_indices, kkt._full_data, b, x, r)
    expected = b - kkt.matvec(x)
    np.testing.assert_array_equal(r, expected)  # SciPy's order of the row sums
    np.testing.assert_allclose(r, b - k_dense @ x, atol=1e-11)
    assert nrm_r == np.abs(r).max() and nrm_x == np.abs(x).max()
    x[7] = np.nan
    nrm_r, nrm_x = _residual_into(pat.full_indptr, pat.full_indices, kkt._full_data, b, x, r)
    assert np.isnan(nrm_r) and np.isnan(nrm_x)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("shift", [1e-3, -0.5])
def test_refined_solve_matches_dense_and_its_fronts_use_the_blocked_kernels(seed, shift):
    kkt, k_dense, diag, rng = _system(seed, shift=shift)
    a = kkt.analysis
    assert np.sum(np.diff(a.sfirst) >= 8) >= 5  # 8-column blocks of the front kernels
    if np.abs(np.linalg.eigvalsh(k_dense)).min() < 1e-6:
        pytest.skip("nearly singular draw")
    assert kkt.factorize(diag, static_reg=1e-9) is not None
    rhs = rng.normal(size=kkt.dim)
    sol, ratio = kkt.solve(rhs)
    assert ratio < 1e-10
    exact = np.linalg.solve(k_dense, rhs)
    np.testing.assert_allclose(sol, exact, atol=1e-9 * np.abs(exact).max())
    # without refinement the solve is the factorization's (regularized) one
    unrefined, _ = kkt.solve(rhs, max_refinement=0)
    reg = np.concatenate([np.full(kkt.n, 1e-9), np.full(kkt.dim - kkt.n, -1e-9)])
    np.testing.assert_allclose(
        (k_dense + np.diag(reg)) @ unrefined, rhs, atol=1e-9 * (1 + np.abs(unrefined).max())
    )


def test_refinement_reports_a_singular_matrix():
    """A repeated equality row makes ``K`` singular: the regularized factorization succeeds,
    refinement against ``K`` cannot remove the residual of an inconsistent right-hand side,
    and the ratio says so (the Newton step then treats ``K`` as singular)."""
    rng = np.random.default_rng(3)
    n, me, mi = 60, 20, 10
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, 0.1)
    hess = sp.tril(hess + 5 * sp.eye(n), format="csr")
    jac_e = jac_e.toarray()
    jac_e[-1] = jac_e[0]
    jac_e = sp.csr_matrix(jac_e)
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(hess, jac_e, jac_i)
    diag = np.concatenate([np.zeros(n + me), -np.ones(mi)])
    assert kkt.factorize(diag, static_reg=1e-9) is not None
    rhs = rng.normal(size=kkt.dim)
    rhs[n + me - 1] = rhs[n] + 1.0  # inconsistent with the repeated row
    sol, ratio = kkt.solve(rhs)
    resid = np.abs(rhs - kkt.matvec(sol)).max()
    assert resid > 0.1  # half the inconsistency at least
    nrm_b = np.abs(rhs).max()
    assert ratio == pytest.approx(resid / (min(np.abs(sol).max(), 1e6 * nrm_b) + nrm_b))
    assert ratio > 1e-10  # not converged: reported, not hidden
    consistent = kkt.matvec(rng.normal(size=kkt.dim))
    sol, ratio = kkt.solve(consistent)
    assert ratio < 1e-10
    np.testing.assert_allclose(kkt.matvec(sol), consistent, atol=1e-8 * np.abs(sol).max())


def test_nonfinite_right_hand_side_gives_an_infinite_ratio():
    kkt, _, diag, rng = _system(1)
    kkt.factorize(diag, static_reg=1e-9)
    rhs = rng.normal(size=kkt.dim)
    rhs[3] = np.inf
    _, ratio = kkt.solve(rhs)
    assert ratio == np.inf


def test_pattern_check_and_block_scatter():
    assert same_arrays(np.arange(5), np.arange(5))
    assert not same_arrays(np.arange(5), np.arange(4))
    assert not same_arrays(np.arange(5), np.array([0, 1, 2, 3, 5]))
    kkt, k_dense, diag, _ = _system(2)
    kkt.factorize(diag)
    np.testing.assert_array_equal(kkt.matrix().toarray(), k_dense)
    # H = 0 keeps the pattern, drops its values
    hess, jac_e, jac_i = _kkt_blocks(np.random.default_rng(2), 240, 108, 30, 0.02, 24)
    kkt.set_matrices(None, jac_e, jac_i)
    kkt.factorize(diag)
    np.testing.assert_array_equal(kkt.matrix().toarray(), _dense(0 * hess, jac_e, jac_i, diag))


def test_wrong_lengths_are_input_errors():
    from mbplan.errors import InputError

    kkt, _, diag, _ = _system(4)
    with pytest.raises(InputError, match="diagonal has shape"):
        kkt.factorize(diag[:-1])
    kkt.factorize(diag, static_reg=1e-9)
    with pytest.raises(InputError, match="rhs has shape"):
        kkt.solve(np.ones(kkt.dim + 1))


def test_factorize_or_solve_before_set_matrices_is_an_input_error():
    from mbplan.errors import InputError

    kkt = KKTSystem(2, 1, 0)
    with pytest.raises(InputError, match="call set_matrices"):
        kkt.factorize(np.zeros(3))
    with pytest.raises(InputError, match="call set_matrices"):
        kkt.solve(np.zeros(3))


def test_blas_thread_limit_is_restored_by_the_last_of_nested_users():
    """The BLAS thread limit is process-wide: nested (or concurrent) users share one limit,
    taken by the first and restored by the last."""
    import threadpoolctl

    from mbplan.solvers.kkt.ldl.supernodal import OneBlasThread

    def blas_threads() -> list[int]:
        return [
            i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"
        ]

    before = blas_threads()
    limit = OneBlasThread()
    with limit:
        with limit:
            assert all(n == 1 for n in blas_threads())
        assert all(n == 1 for n in blas_threads())  # the outer user still holds the limit
    assert blas_threads() == before
