"""Threshold pivoting inside the supernodes of the LDLᵀ (``KKTSystem(pivot_threshold=u)``):
inertia and steps against dense linear algebra and against the unpivoted factorization, on
random KKT systems, zero-diagonal blocks that need 2 × 2 pivots, singular and wrong-inertia
matrices, and the first RIPM KKT matrix of a chain, which breaks the unpivoted LDLᵀ down with
a METIS order."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_linear_solver import (
    CASES,
    _dense,
    _grid_blocks,
    _kkt_blocks,
    _kkt_blocks_without_empty_eq_rows,
)

from mbplan.errors import InputError
from mbplan.solvers import RIPMOptions, solve_ripm
from mbplan.solvers.kkt.system import KKTSystem

NONSINGULAR = [c for c in CASES[1:] if c[0] != 40]  # (40, 12, 10): structurally singular


def _expected_inertia(k_dense):
    ev = np.linalg.eigvalsh(k_dense)
    return int(np.sum(ev > 0)), int(np.sum(ev < 0)), float(np.abs(ev).min())


@pytest.mark.parametrize("u", [1e-10, 0.01, 0.5])
@pytest.mark.parametrize("ordering", ["amd", "metis"])
@pytest.mark.parametrize("case", NONSINGULAR)
def test_pivoted_inertia_and_steps_match_dense_linear_algebra(case, ordering, u):
    """Positive, zero and negative primal diagonals (wrong inertia), zero equality diagonals:
    the pivoted factorization's inertia is the dense eigenvalues' and its refined step the
    dense solve's."""
    n, me, mi = case[:3]
    blocks, rng = _kkt_blocks_without_empty_eq_rows(case)
    kkt = KKTSystem(n, me, mi, ordering=ordering, pivot_threshold=u)
    kkt.set_matrices(*blocks)
    checked = 0
    for shift in (1e-3, 0.0, -0.5):
        diag = np.concatenate([np.full(n, shift), np.zeros(me), -rng.uniform(0.1, 1, mi)])
        k_dense = _dense(*blocks, diag)
        pos, neg, smallest = _expected_inertia(k_dense)
        if smallest < 1e-6:
            continue  # numerically singular draw: no inertia to compare with
        inertia = kkt.factorize(diag, static_reg=1e-9)
        assert inertia is not None
        assert (inertia.positive, inertia.negative, inertia.zero) == (pos, neg, 0)
        rhs = rng.normal(size=kkt.dim)
        sol, ratio = kkt.solve(rhs)
        assert ratio < 1e-10
        exact = np.linalg.solve(k_dense, rhs)
        np.testing.assert_allclose(sol, exact, atol=1e-8 * np.abs(exact).max())
        checked += 1
    assert checked >= 1


def test_zero_diagonal_front_needs_two_by_two_pivots():
    """A dense symmetric matrix with a zero diagonal (one supernode): the unpivoted LDLᵀ breaks
    down on its first pivot; pivoting inside the supernode takes 2 × 2 pivots and gives the
    exact inertia and solve."""
    rng = np.random.default_rng(5)
    n = 12
    a = rng.normal(size=(n, n))
    h = a + a.T
    np.fill_diagonal(h, 0.0)
    hess = sp.csr_matrix(np.tril(h))
    plain = KKTSystem(n, 0, 0)
    plain.set_matrices(hess, None, None)
    assert plain.factorize(np.zeros(n)) is None
    kkt = KKTSystem(n, 0, 0, pivot_threshold=0.01)
    kkt.set_matrices(hess, None, None)
    inertia = kkt.factorize(np.zeros(n))
    assert len(kkt.analysis.sfirst) == 2  # one supernode
    pos, neg, _ = _expected_inertia(h)
    assert (inertia.positive, inertia.negative, inertia.zero) == (pos, neg, 0)
    stats = kkt.pivot_stats
    assert stats["two_by_two"] >= 1 and stats["perturbed"] == 0
    rhs = rng.normal(size=n)
    sol, ratio = kkt.solve(rhs)
    assert ratio < 1e-10
    np.testing.assert_allclose(sol, np.linalg.solve(h, rhs), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("shape", [(12, 5), (4, 16)])
def test_pivoted_metis_and_unpivoted_amd_agree_on_grid_kkt_systems(shape):
    rng = np.random.default_rng(sum(shape))
    blocks = _grid_blocks(rng, *shape)
    n, me, mi = blocks[0].shape[0], blocks[1].shape[0], blocks[2].shape[0]
    systems = [
        KKTSystem(n, me, mi),
        KKTSystem(n, me, mi, ordering="metis", pivot_threshold=1e-10),
        KKTSystem(n, me, mi, ordering="metis", pivot_threshold=0.1),
    ]
    for kkt in systems:
        kkt.set_matrices(*blocks)
    rhs = rng.normal(size=n + me + mi)
    for shift in (1e-2, -2.0):
        diag = np.concatenate([np.full(n, shift), np.zeros(me), -np.ones(mi)])
        inertias = [kkt.factorize(diag, static_reg=1e-9) for kkt in systems]
        assert inertias[0] is not None and all(i == inertias[0] for i in inertias)
        steps = [kkt.solve(rhs)[0] for kkt in systems]
        for step in steps[1:]:
            np.testing.assert_allclose(step, steps[0], atol=1e-8 * np.abs(steps[0]).max())


def test_singular_matrix_with_pivoting_is_reported_by_refinement():
    """A repeated equality row: without static regularization the pivoted factorization
    perturbs the zero pivots that no pivot of their supernode can replace (counted); with or
    without it, refinement against ``K`` cannot remove the residual of an inconsistent
    right-hand side and says so, and solves a consistent one."""
    rng = np.random.default_rng(3)
    n, me, mi = 60, 20, 10
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, 0.1)
    hess = sp.tril(hess + 5 * sp.eye(n), format="csr")
    jac_e = jac_e.toarray()
    jac_e[-1] = jac_e[0]
    jac_e = sp.csr_matrix(jac_e)
    diag = np.concatenate([np.zeros(n + me), -np.ones(mi)])
    rhs = rng.normal(size=n + me + mi)
    rhs[n + me - 1] = rhs[n] + 1.0  # inconsistent with the repeated row
    for u in (1e-10, 0.01):
        for eps in (0.0, 1e-9):
            kkt = KKTSystem(n, me, mi, pivot_threshold=u)
            kkt.set_matrices(hess, jac_e, jac_i)
            assert kkt.factorize(diag, eps) is not None
            assert kkt.pivot_stats["perturbed"] >= (1 if eps == 0.0 else 0)
            _, ratio = kkt.solve(rhs)
            assert ratio > 1e-10  # not converged: reported, not hidden
            consistent = kkt.matvec(rng.normal(size=kkt.dim))
            sol, ratio = kkt.solve(consistent)
            assert ratio < 1e-10
            np.testing.assert_allclose(kkt.matvec(sol), consistent, atol=1e-8 * np.abs(sol).max())


def _first_ripm_kkt(problem, x0, options) -> tuple[tuple, np.ndarray]:
    """The blocks and diagonal of the first full KKT matrix of a RIPM solve (``δ_w = 0``)."""
    saved: dict = {}
    factorize, set_matrices = KKTSystem.factorize, KKTSystem.set_matrices
    dim = problem.n + problem.n_eq + problem.n_ineq

    def capture_blocks(self, *blocks):
        if self.dim == dim and "diagonal" not in saved:
            saved["blocks"] = tuple(b.copy() if b is not None else None for b in blocks)
        return set_matrices(self, *blocks)

    def capture(self, diagonal, static_reg=0.0):
        if self.dim == dim and "diagonal" not in saved and not np.any(diagonal[: self.n]):
            saved["diagonal"] = diagonal.copy()
        return factorize(self, diagonal, static_reg)

    KKTSystem.factorize, KKTSystem.set_matrices = capture, capture_blocks
    try:
        solve_ripm(problem, x0, options.replace(max_iter=1, kkt_method="full"))
    finally:
        KKTSystem.factorize, KKTSystem.set_matrices = factorize, set_matrices
    return saved["blocks"], saved["diagonal"]


@pytest.fixture(scope="module")
def chain_first_kkt():
    """The first RIPM KKT matrix (δ_w = 0) of a 4-link chain reach with N = 6."""

    from mbplan.tasks.speed import chain_task, maximal_ripm_problem

    problem, x0 = maximal_ripm_problem(chain_task(4, N=6), "linear")
    blocks, diag = _first_ripm_kkt(problem, x0, RIPMOptions(tol=1e-6))
    return problem, x0, blocks, diag


def test_first_chain_kkt_breaks_unpivoted_metis_and_not_the_pivoted_one(chain_first_kkt):
    problem, _, blocks, diag = chain_first_kkt
    n, me, mi = problem.n, problem.n_eq, problem.n_ineq
    systems = {
        (o, u): KKTSystem(n, me, mi, ordering=o, pivot_threshold=u)
        for o in ("amd", "metis")
        for u in (0.0, 1e-10, 0.01)
    }
    inertia = {}
    for key, kkt in systems.items():
        kkt.set_matrices(*blocks)
        inertia[key] = kkt.factorize(diag, 1e-9)
    assert inertia["metis", 0.0] is None  # unpivoted METIS breaks down here
    expected = (n, me + mi, 0)
    rhs = np.random.default_rng(0).normal(size=n + me + mi)
    ref = systems["amd", 0.0].solve(rhs)[0]
    for key, kkt in systems.items():
        if key == ("metis", 0.0):
            continue
        got = inertia[key]
        assert (got.positive, got.negative, got.zero) == expected, key
        sol, ratio = kkt.solve(rhs)
        assert ratio < 1e-10
        np.testing.assert_allclose(sol, ref, atol=1e-7 * np.abs(ref).max())
    assert systems["metis", 1e-10].pivot_stats["pivoted_fronts"] >= 1


def test_ripm_with_pivoted_metis_matches_amd_on_the_chain(chain_first_kkt):

    problem, x0, _, _ = chain_first_kkt
    opts = RIPMOptions(tol=1e-6)
    amd = solve_ripm(problem, x0, opts)
    metis = solve_ripm(problem, x0, opts.replace(kkt_ordering="metis", kkt_pivot_threshold=1e-10))
    assert amd.success and metis.success
    assert metis.iterations == amd.iterations
    assert metis.n_factorizations == amd.n_factorizations  # no δ_w from a breakdown
    np.testing.assert_allclose(metis.objective, amd.objective, rtol=1e-8)


def test_pivot_threshold_out_of_range_is_an_input_error():
    with pytest.raises(InputError, match="pivot_threshold"):
        KKTSystem(2, 1, 0, pivot_threshold=2.0)
    with pytest.raises(InputError, match="kkt_pivot_threshold"):
        RIPMOptions(kkt_pivot_threshold=-1.0)
