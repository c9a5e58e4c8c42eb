"""The supernodal LDLᵀ behind the RIPM's KKT system: exact inertia, solves, breakdowns and the
symbolic analysis shared through a workspace, on matrices whose fronts exercise every kernel
path."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mbplan.solvers.kkt.system import KKTSystem
from mbplan.workspace import Workspace


def _kkt_blocks(rng, n, me, mi, density, band=None):
    """Random ``H`` (lower), ``A_E``, ``A_I``; with ``band`` a block-banded (trajectory-like)
    structure: knots of ``band`` variables coupled to the next knot only."""
    if band is None:
        h = sp.random(n, n, density=density, random_state=rng, format="csr")
        hess = sp.tril(h + h.T, format="csr")
        jac_e = sp.random(me, n, density=density, random_state=rng, format="csr")
        jac_i = sp.random(mi, n, density=density, random_state=rng, format="csr")
        return hess, jac_e, jac_i
    knots = n // band
    blocks = [rng.normal(size=(band, band)) for _ in range(knots)]
    hess = sp.tril(sp.block_diag([b + b.T for b in blocks]), format="csr")
    rows_e = []
    for k in range(knots - 1):  # "dynamics": knot k+1 minus a dense map of knot k
        row = np.zeros((band // 2, n))
        row[:, (k + 1) * band : (k + 1) * band + band // 2] = np.eye(band // 2)
        row[:, k * band : (k + 1) * band] = rng.normal(size=(band // 2, band))
        rows_e.append(row)
    jac_e = sp.csr_matrix(np.vstack(rows_e)[:me])
    jac_i = sp.random(mi, n, density=density, random_state=rng, format="csr")
    return hess, jac_e, jac_i


def _kkt_blocks_without_empty_eq_rows(case):
    """:func:`_kkt_blocks` of ``case`` (seeded by its size) with a one added to every equality
    row (an empty one, with its zero diagonal, would make ``K`` singular); and the generator."""
    n, me, mi, density, band = case
    rng = np.random.default_rng(n + me + 1)
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, density, band)
    ones = sp.csr_matrix((np.ones(me), (np.arange(me), rng.integers(0, n, me))), (me, n))
    return (hess, (jac_e + ones).tocsr(), jac_i), rng


def _dense(hess, jac_e, jac_i, diag):
    h = hess.toarray()
    h = h + np.tril(h, -1).T
    a = np.vstack([jac_e.toarray(), jac_i.toarray()])
    k = np.block([[h, a.T], [a, np.zeros((a.shape[0], a.shape[0]))]])
    return k + np.diag(diag)


CASES = [
    # (n, n_eq, n_ineq, density, band)
    (1, 0, 0, 1.0, None),
    (6, 2, 3, 0.5, None),
    (40, 12, 10, 0.15, None),
    (120, 30, 40, 0.03, None),
    (240, 108, 30, 0.02, 24),  # dense knot-to-knot fronts: blocked kernels, odd sizes
    (300, 132, 20, 0.01, 25),
]


@pytest.mark.parametrize(("n", "me", "mi", "density", "band"), CASES)
def test_inertia_and_solve_match_dense_linear_algebra(n, me, mi, density, band):
    rng = np.random.default_rng(n + me)
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, density, band)
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(hess, jac_e, jac_i)
    for shift in (1e-3, 2.0, -0.5):  # positive, mixed and wrong inertias
        diag = np.concatenate([np.full(n, shift), -rng.uniform(0.1, 1, me), -rng.random(mi)])
        inertia = kkt.factorize(diag, static_reg=1e-9)
        k_dense = _dense(hess, jac_e, jac_i, diag)
        eig = np.linalg.eigvalsh(k_dense)
        if np.abs(eig).min() < 1e-6:
            continue
        assert inertia is not None
        assert (inertia.positive, inertia.negative, inertia.zero) == (
            np.sum(eig > 0),
            np.sum(eig < 0),
            0,
        )
        np.testing.assert_allclose(kkt.matrix().toarray(), k_dense, atol=1e-14)
        rhs = rng.normal(size=n + me + mi)
        sol, ratio = kkt.solve(rhs)
        assert ratio < 1e-10
        np.testing.assert_allclose(k_dense @ sol, rhs, atol=1e-8 * (1 + np.abs(sol).max()))


def test_refinement_steps_between_the_minimum_and_the_ratio():
    """``min_refinement=0``: no refinement step when the first solve meets ``ratio_max`` (the
    solution of ``max_refinement=0``); IPOPT's ``1``: one step even then (the static
    regularization's error removed); a ratio the first solve misses is refined to either way."""
    rng = np.random.default_rng(7)
    n, me, mi = 120, 30, 40
    hess, jac_e, jac_i = _kkt_blocks(rng, n, me, mi, 0.03)
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(hess, jac_e, jac_i)
    diag = np.concatenate([np.full(n, 2.0), -rng.uniform(0.1, 1, me), -rng.random(mi)])
    assert kkt.factorize(diag, static_reg=1e-6) is not None  # a first solve at ratio ~1e-6
    rhs = rng.normal(size=n + me + mi)
    first, first_ratio = kkt.solve(rhs, 0)
    assert 1e-12 < first_ratio < 1e-3
    loose, loose_ratio = kkt.solve(rhs, 10, 1e-3, min_refinement=0)
    np.testing.assert_array_equal(loose, first)
    assert loose_ratio == first_ratio
    once, once_ratio = kkt.solve(rhs, 10, 1e-3, min_refinement=1)
    assert once_ratio < 1e-3 * first_ratio
    tight, tight_ratio = kkt.solve(rhs, 10, 1e-10, min_refinement=0)
    assert tight_ratio <= 1e-10 and np.abs(tight - once).max() < 1e-8 * np.abs(once).max()


def test_zero_or_nonfinite_pivot_is_a_breakdown():
    kkt = KKTSystem(1, 1, 0)
    kkt.set_matrices(None, sp.csr_matrix([[1.0]]), None)
    assert kkt.factorize(np.zeros(2)) is None  # [[0, 1], [1, 0]] without regularization
    inertia = kkt.factorize(np.zeros(2), static_reg=1e-9)
    assert (inertia.positive, inertia.negative, inertia.zero) == (1, 1, 0)
    assert kkt.factorize(np.array([np.nan, 0.0]), static_reg=1e-9) is None
    assert kkt.factorize(np.array([1.0, -1.0])) is not None  # usable again after a breakdown


def test_systems_sharing_a_pattern_share_the_analysis_not_the_factors():
    rng = np.random.default_rng(3)
    hess, jac_e, jac_i = _kkt_blocks(rng, 50, 20, 10, 0.1, None)
    ws = Workspace()
    first, second = (KKTSystem(50, 20, 10, workspace=ws) for _ in range(2))
    first.set_matrices(hess, jac_e, jac_i)
    second.set_matrices(2 * hess, jac_e, jac_i)
    assert first._solver.a is second._solver.a
    alone = KKTSystem(50, 20, 10)  # no workspace: its own analysis (an equal one)
    alone.set_matrices(hess, jac_e, jac_i)
    assert alone._solver.a is not first._solver.a
    np.testing.assert_array_equal(alone._solver.a.perm, first._solver.a.perm)
    d1 = np.concatenate([np.full(50, 3.0), np.full(20, -1e-3), -np.ones(10)])
    d2 = np.concatenate([np.full(50, 0.1), np.full(20, -1.0), -np.full(10, 2.0)])
    first.factorize(d1)
    second.factorize(d2)  # must not overwrite the first system's factors
    rhs = rng.normal(size=80)
    sol, _ = first.solve(rhs)
    np.testing.assert_allclose(_dense(hess, jac_e, jac_i, d1) @ sol, rhs, atol=1e-8)


def test_a_released_workspace_serves_the_next_system_of_its_pattern():
    """A system hands its work arrays back to its pattern when it is gone (or changes pattern);
    the next system of that pattern takes them and factorizes and solves exactly as a fresh one,
    while systems alive at once never share them."""
    rng = np.random.default_rng(5)
    hess, jac_e, jac_i = _kkt_blocks(rng, 60, 24, 12, 0.08, None)
    d = np.concatenate([np.full(60, 2.0), np.full(24, -1e-2), -np.ones(12)])
    rhs = rng.normal(size=96)

    def solve(kkt):
        kkt.set_matrices(hess, jac_e, jac_i)
        inertia = kkt.factorize(d, static_reg=1e-9)
        return inertia, kkt.solve(rhs)

    ws = Workspace()
    first = KKTSystem(60, 24, 12, workspace=ws)
    expected = solve(first)
    arrays = first._factor_data, first._solver
    del first
    second = KKTSystem(60, 24, 12, workspace=ws)
    got = solve(second)
    assert second._factor_data is arrays[0] and second._solver is arrays[1]  # reused
    assert got[0] == expected[0] and got[1][1] == expected[1][1]
    np.testing.assert_array_equal(got[1][0], expected[1][0])
    third = KKTSystem(60, 24, 12, workspace=ws)
    solve(third)
    assert third._solver is not second._solver and third._factor_data is not arrays[0]
    second.set_matrices(*_kkt_blocks(rng, 60, 24, 12, 0.08, None))  # another pattern
    fourth = KKTSystem(60, 24, 12, workspace=ws)
    np.testing.assert_array_equal(solve(fourth)[1][0], expected[1][0])
    assert fourth._solver is arrays[1]  # released by the change of pattern


def _grid_blocks(rng, knots, bodies, dim=3):
    """A time × body grid of dense ``dim`` blocks (the maximal-coordinate KKT structure):
    ``H`` couples each block to itself, equality rows tie a block to its neighbour in time and
    in the chain of bodies."""
    n = knots * bodies * dim

    def idx(k, b):
        return (k * bodies + b) * dim + np.arange(dim)

    blocks = [rng.normal(size=(dim, dim)) for _ in range(knots * bodies)]
    hess = sp.tril(sp.block_diag([b + b.T for b in blocks]), format="csr")
    rows = []
    for k in range(knots):
        for b in range(bodies):
            for k2, b2 in ((k + 1, b), (k, b + 1)):
                if k2 < knots and b2 < bodies:
                    row = np.zeros((1, n))
                    row[0, idx(k, b)] = rng.normal(size=dim)
                    row[0, idx(k2, b2)] = rng.normal(size=dim)
                    rows.append(row)
    jac_e = sp.csr_matrix(np.vstack(rows))
    jac_i = sp.csr_matrix(np.eye(n)[:: 2 * dim])
    return hess, jac_e, jac_i


@pytest.mark.parametrize("ordering", ["nested", "metis"])
@pytest.mark.parametrize("shape", [(12, 5), (30, 2), (4, 16)])
def test_dissection_orders_and_amd_give_the_same_inertia_and_steps(shape, ordering):
    """Both elimination orders factorize the same matrix: same pivot signs (Sylvester),
    same solutions; a singular matrix (duplicated constraint row) is flagged by both through
    the refinement residual, a wrong inertia is reported by both."""
    rng = np.random.default_rng(sum(shape))
    hess, jac_e, jac_i = _grid_blocks(rng, *shape)
    n, me, mi = hess.shape[0], jac_e.shape[0], jac_i.shape[0]
    systems = {o: KKTSystem(n, me, mi, ordering=o) for o in ("amd", ordering)}
    for kkt in systems.values():
        kkt.set_matrices(hess, jac_e, jac_i)
    assert not np.array_equal(systems["amd"].analysis.perm, systems[ordering].analysis.perm)
    for shift in (1e-2, 3.0, -0.7):
        diag = np.concatenate([np.full(n, shift), -rng.uniform(0.1, 1, me), -rng.random(mi)])
        eig = np.linalg.eigvalsh(_dense(hess, jac_e, jac_i, diag))
        rhs = rng.normal(size=n + me + mi)
        sols = []
        for kkt in systems.values():
            inertia = kkt.factorize(diag, static_reg=1e-9)
            assert (inertia.positive, inertia.negative) == (np.sum(eig > 0), np.sum(eig < 0))
            sol, ratio = kkt.solve(rhs)
            assert ratio < 1e-10
            sols.append(sol)
        np.testing.assert_allclose(sols[0], sols[1], atol=1e-8 * (1 + np.abs(sols[0]).max()))
    # singular: a repeated equality row and a zero dual diagonal. The static regularization
    # turns the zero pivot into ±ε: both orders give the same pivot signs and a solution of
    # size ~1/ε (the residual ratio alone does not reveal the singularity)
    jac_s = sp.vstack([jac_e, jac_e[:1]], format="csr")
    diag = np.concatenate([np.full(n, 20.0), np.zeros(me + 1), -np.ones(mi)])  # H + 20 I > 0
    rhs = rng.normal(size=n + me + 1 + mi)
    found = []
    for o in ("amd", ordering):
        kkt = KKTSystem(n, me + 1, mi, ordering=o)
        kkt.set_matrices(hess, jac_s, jac_i)
        inertia = kkt.factorize(diag, static_reg=1e-9)
        sol, _ = kkt.solve(rhs)
        found.append((inertia.positive, inertia.negative))
        assert np.abs(sol).max() > 1e6 * np.abs(rhs).max(), o
    assert found[0] == found[1]


def _laplacian_3d(m):
    t = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(m, m))
    eye = sp.eye(m)
    return sp.tril(
        sp.kron(sp.kron(t, eye), eye)
        + sp.kron(sp.kron(eye, t), eye)
        + sp.kron(eye, sp.kron(eye, t)),
        format="csr",
    )


@pytest.mark.parametrize(
    ("blocks", "expected"),
    [
        (_grid_blocks(np.random.default_rng(0), 20, 12), "amd"),
        ((_laplacian_3d(10),), "amd"),  # METIS has fewer flops, AMD's are below the threshold
        ((_laplacian_3d(14),), "metis"),
    ],
)
def test_auto_ordering_keeps_the_analysis_with_fewer_flops(blocks, expected):
    """``"auto"`` is AMD's kept analysis, or METIS's when AMD's factorization reaches
    ``AUTO_MIN_FLOPS`` and METIS predicts fewer multiply-adds: AMD on a thin time × body grid
    and on a small 3-D grid, METIS on a larger 3-D grid."""
    from mbplan.solvers.kkt.pattern import AUTO_MIN_FLOPS

    hess, *jacs = blocks
    n = hess.shape[0]
    me, mi = (j.shape[0] for j in jacs) if jacs else (0, 0)
    ws = Workspace()
    systems = {o: KKTSystem(n, me, mi, ordering=o, workspace=ws) for o in ("amd", "metis", "auto")}
    for kkt in systems.values():
        kkt.set_matrices(hess, *(jacs or (None, None)))
    assert systems["auto"].analysis is systems[expected].analysis
    flops = {o: systems[o].analysis.flops for o in ("amd", "metis")}
    worth_trying = flops["amd"] >= AUTO_MIN_FLOPS
    assert (expected == "metis") == (worth_trying and flops["metis"] < flops["amd"])


@pytest.mark.parametrize("ordering", ["nested", "metis", "auto"])
def test_ripm_steps_do_not_depend_on_the_ordering(ordering):
    from reference_problems import BandedControlNLP

    from mbplan.solvers import solve_ripm

    prob = BandedControlNLP(nx=4, nu=2, horizon=20)
    runs = [solve_ripm(prob, prob.initial_guess(), kkt_ordering=o) for o in ("amd", ordering)]
    assert runs[0].success and runs[1].success
    assert runs[0].iterations == runs[1].iterations
    kkt_errors = [r.history.kkt_error for r in runs]
    np.testing.assert_allclose(*kkt_errors, rtol=1e-5, atol=1e-13)  # rounding near E_0 = 1e-10
    np.testing.assert_allclose(runs[0].x, runs[1].x, atol=1e-8)


@pytest.mark.parametrize("case", [c for c in CASES if c[-1]])
def test_blas_update_of_large_fronts_matches_the_blocked_kernels(case, monkeypatch):
    """The BLAS Schur update (fronts with at least ``BLAS_FRONT_ROWS`` update rows, lowered here
    so that the banded cases reach it) gives the blocked kernels' inertia, pivots and steps, on
    positive, mixed and wrong inertias."""
    from mbplan.solvers.kkt.ldl import supernodal as supernodal_ldl

    n, me, mi, density, band = case
    rng = np.random.default_rng(n + me)
    blocks = _kkt_blocks(rng, n, me, mi, density, band)
    systems = []
    for rows in (10**9, 8):
        monkeypatch.setattr(supernodal_ldl, "BLAS_FRONT_ROWS", rows)
        kkt = KKTSystem(n, me, mi)
        kkt.set_matrices(*blocks)
        systems.append(kkt)
    assert systems[1]._solver.uses_blas and not systems[0]._solver.uses_blas
    rhs = rng.normal(size=n + me + mi)
    for shift in (1e-3, 2.0, -0.5):
        diag = np.concatenate([np.full(n, shift), -np.linspace(0.1, 1, me), -np.ones(mi)])
        plain, blas = (kkt.factorize(diag, static_reg=1e-9) for kkt in systems)
        assert plain == blas
        d_plain, d_blas = (kkt._solver.d for kkt in systems)
        np.testing.assert_allclose(d_blas, d_plain, rtol=1e-8, atol=1e-10)
        steps = [kkt.solve(rhs)[0] for kkt in systems]
        np.testing.assert_allclose(steps[1], steps[0], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("case", [c for c in CASES if c[-1]])
def test_banded_cases_exercise_the_blocked_kernels(case):
    """The dense knot-to-knot fronts of the banded cases reach the 4 x 4 kernels (fronts with
    at least ``_WIDE`` rows below four or more pivot columns), which the test above checks."""
    from mbplan.solvers.kkt.ldl.kernels import _WIDE

    n, me, mi, density, band = case
    kkt = KKTSystem(n, me, mi)
    kkt.set_matrices(*_kkt_blocks(np.random.default_rng(n + me), n, me, mi, density, band))
    a = kkt.analysis
    k, m = np.diff(a.sfirst), np.diff(a.fptr)
    assert np.sum((k >= 4) & (m - k >= _WIDE)) >= 10
