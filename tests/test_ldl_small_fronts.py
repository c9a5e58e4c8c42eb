"""The LDLᵀ's paths for small supernodes (see docs/ripm-design.md): leaf
supernodes that subtract their Schur update straight from their parent's front, sibling leaves
with equal rows merged into one supernode, kernels on borrowed arrays — against dense linear
algebra, against the factorization without them, with pivoting, breakdowns and wrong
inertias."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest
import scipy.sparse as sp
from test_linear_solver import CASES, _dense, _kkt_blocks, _kkt_blocks_without_empty_eq_rows

from mbplan.solvers.kkt.borrow import borrowed
from mbplan.solvers.kkt.ldl import layout as ldl_layout
from mbplan.solvers.kkt.system import KKTSystem


def _pivots_by_variable(kkt):
    """``D`` indexed by the original unknowns (orders that differ only in the order of
    independent columns give the same pivots)."""
    d = np.empty(kkt.dim)
    d[kkt.analysis.perm] = kkt._solver.d
    return d


def _control_blocks(rng, knots=10, dim=6, nu=3, zero_control=None):
    """Knots of ``dim`` states (dense Hessian block) and ``nu`` controls (diagonal Hessian,
    ``0`` for control ``zero_control`` of knot 1), dynamics ``x_{k+1} = A x_k + B u_k`` with
    dense ``A``, ``B``, bounds on the first state of each knot. The controls of a knot enter
    the same rows only: AMD eliminates them as sibling leaves with equal rows."""
    nk = dim + nu
    n = knots * nk
    hess = sp.lil_matrix((n, n))
    rows = []
    for k in range(knots):
        x, u = k * nk + np.arange(dim), k * nk + dim + np.arange(nu)
        b = rng.normal(size=(dim, dim))
        hess[np.ix_(x, x)] = b @ b.T + np.eye(dim)
        hess[u, u] = rng.uniform(0.5, 2.0, nu)
        if k + 1 < knots:
            row = np.zeros((dim, n))
            row[:, (k + 1) * nk + np.arange(dim)] = np.eye(dim)
            row[:, x] = -rng.normal(size=(dim, dim))
            row[:, u] = -rng.normal(size=(dim, nu))
            rows.append(row)
    if zero_control is not None:
        hess[nk + dim + zero_control, nk + dim + zero_control] = 0.0
    return (
        sp.tril(hess, format="csr"),
        sp.csr_matrix(np.vstack(rows)),
        sp.csr_matrix(np.eye(n)[::nk]),
    )


def _without_small_front_paths(monkeypatch):
    """Analyses built from now on without direct leaves or merged siblings (every front through
    its own update matrix; a KKT system without a workspace builds its own, and none is read
    from the disk cache, whose keys do not hold the patched constant)."""
    monkeypatch.setattr(ldl_layout, "DIRECT_COLUMNS", 0)
    monkeypatch.setenv("MBPLAN_DISK_CACHE", "off")


@pytest.mark.parametrize("case", [*CASES[2:], "control"])
def test_direct_leaves_and_merged_siblings_match_update_matrices(case, monkeypatch):
    """The default analysis (direct leaves, merged siblings on the control problem) and one
    without either give the same pivots, the dense eigenvalues' inertia and the dense solve,
    on positive, mixed and wrong inertias."""
    rng = np.random.default_rng(7)
    if case == "control":
        blocks = _control_blocks(rng)
    else:
        blocks = _kkt_blocks(rng, *case)
    n, me, mi = (b.shape[0] for b in blocks)
    new = KKTSystem(n, me, mi)
    new.set_matrices(*blocks)
    _without_small_front_paths(monkeypatch)
    old = KKTSystem(n, me, mi)
    old.set_matrices(*blocks)
    a, b = new.analysis, old.analysis
    assert a.direct.any() and not b.direct.any()
    if case == "control":
        assert len(a.sfirst) < len(b.sfirst)  # sibling controls merged
        assert np.diff(a.sfirst)[a.direct].max() > 1
    rhs = rng.normal(size=n + me + mi)
    for shift in (1e-3, 2.0, -0.5):
        diag = np.concatenate([np.full(n, shift), -rng.uniform(0.1, 1, me), -rng.random(mi)])
        eig = np.linalg.eigvalsh(_dense(*blocks, diag))
        inertia = [kkt.factorize(diag, static_reg=1e-9) for kkt in (new, old)]
        assert inertia[0] == inertia[1]
        assert (inertia[0].positive, inertia[0].negative) == (np.sum(eig > 0), np.sum(eig < 0))
        np.testing.assert_allclose(
            _pivots_by_variable(new), _pivots_by_variable(old), rtol=1e-9, atol=1e-12
        )
        if np.abs(eig).min() < 1e-6:
            continue
        exact = np.linalg.solve(_dense(*blocks, diag), rhs)
        for kkt in (new, old):
            sol, ratio = kkt.solve(rhs)
            assert ratio < 1e-10
            np.testing.assert_allclose(sol, exact, atol=1e-8 * np.abs(exact).max())


def test_zero_pivot_of_a_direct_leaf_is_a_breakdown():
    """A control with a zero Hessian diagonal, eliminated in a merged leaf that updates its
    parent directly: its zero pivot breaks the unpivoted LDLᵀ down; with the static
    regularization, or with pivoting (a perturbed pivot), the inertia is the dense one and
    refinement solves ``K``."""
    rng = np.random.default_rng(2)
    blocks = _control_blocks(rng, zero_control=1)
    n, me, mi = (b.shape[0] for b in blocks)
    zero = 9 + 6 + 1  # knot 1, control 1
    diag = np.concatenate([np.zeros(n + me), -np.ones(mi)])
    k_dense = _dense(*blocks, diag)
    eig = np.linalg.eigvalsh(k_dense)
    assert np.abs(eig).min() > 1e-6
    rhs = rng.normal(size=n + me + mi)
    plain = KKTSystem(n, me, mi)
    plain.set_matrices(*blocks)
    a = plain.analysis
    front = np.searchsorted(a.sfirst, np.flatnonzero(a.perm == zero)[0], side="right") - 1
    assert a.direct[front] and a.sfirst[front + 1] - a.sfirst[front] > 1
    assert plain.factorize(diag) is None
    for kkt, reg in ((plain, 1e-9), (KKTSystem(n, me, mi, pivot_threshold=0.01), 0.0)):
        kkt.set_matrices(*blocks)
        inertia = kkt.factorize(diag, static_reg=reg)
        assert (inertia.positive, inertia.negative, inertia.zero) == (
            np.sum(eig > 0),
            np.sum(eig < 0),
            0,
        )
        sol, ratio = kkt.solve(rhs)
        assert ratio < 1e-10
        exact = np.linalg.solve(k_dense, rhs)
        np.testing.assert_allclose(sol, exact, atol=1e-8 * np.abs(exact).max())


@pytest.mark.parametrize("u", [0.01, 0.5])
@pytest.mark.parametrize("case", [c for c in CASES[3:]])
def test_pivoted_leaves_and_parents_of_direct_leaves_match_dense(case, u):
    """Zero equality diagonals with threshold pivoting: leaves that fail the threshold take
    the pivoted path (their update matrix built as before), parents that fail it reassemble
    their pivot columns with their direct children's updates sent again; inertia and steps
    are the dense ones."""
    n, me, mi = case[:3]
    (hess, jac_e, jac_i), rng = _kkt_blocks_without_empty_eq_rows(case)
    kkt = KKTSystem(n, me, mi, pivot_threshold=u)
    kkt.set_matrices(hess, jac_e, jac_i)
    a, f = kkt.analysis, kkt._solver
    for shift in (1e-3, -0.5):
        diag = np.concatenate([np.full(n, shift), np.zeros(me), -rng.uniform(0.1, 1, mi)])
        k_dense = _dense(hess, jac_e, jac_i, diag)
        eig = np.linalg.eigvalsh(k_dense)
        inertia = kkt.factorize(diag, static_reg=1e-9)
        assert (inertia.positive, inertia.negative) == (np.sum(eig > 0), np.sum(eig < 0))
        assert np.any(f.spiv & a.direct)  # a leaf pivoted
        assert any(
            f.spiv[s] and f.sent[a.child[a.cptr[s] : a.cptr[s + 1]]].any()
            for s in range(len(a.sfirst) - 1)
        )  # a front pivoted after direct children had sent their updates
        rhs = rng.normal(size=kkt.dim)
        sol, ratio = kkt.solve(rhs)
        assert ratio < 1e-10
        exact = np.linalg.solve(k_dense, rhs)
        np.testing.assert_allclose(sol, exact, atol=1e-8 * np.abs(exact).max())


@nb.njit
def _write_through(x, value):
    view = borrowed(x)
    view[1:] = value
    return view.shape[0], view[0]


def test_borrowed_view_shares_the_data():
    x = np.arange(4.0)
    assert _write_through(x, -1.0) == (4, 0.0)
    np.testing.assert_array_equal(x, [0.0, -1.0, -1.0, -1.0])


@pytest.mark.parametrize("case", [*CASES[1:], "control"])
def test_update_matrices_alive_at_once_do_not_share_memory(case):
    """Each update matrix lives from its first direct child's step (or its own) to its
    parent's; any two alive at a common step occupy disjoint parts of the buffer, every one
    inside it, and every one is zeroed when it starts."""
    rng = np.random.default_rng(3)
    blocks = _control_blocks(rng) if case == "control" else _kkt_blocks(rng, *case)
    kkt = KKTSystem(*(b.shape[0] for b in blocks))
    kkt.set_matrices(*blocks)
    a = kkt.analysis
    ns = len(a.sfirst) - 1
    size = (np.diff(a.fptr) - np.diff(a.sfirst)) ** 2
    start = np.arange(ns)
    for s in range(ns):
        if a.direct[s]:
            start[a.sparent[s]] = min(start[a.sparent[s]], s)
    end = np.where(a.sparent >= 0, a.sparent, np.arange(ns))
    live = np.flatnonzero(size > 0)
    assert np.all(a.uoff[live] + size[live] <= a.uoff[-1])
    if len(live) > 20:
        assert a.uoff[-1] < size.sum()  # memory is reused
    for i, s in enumerate(live):
        for t in live[:i]:
            if start[s] <= end[t] and start[t] <= end[s]:
                assert a.uoff[s] + size[s] <= a.uoff[t] or a.uoff[t] + size[t] <= a.uoff[s]
    zeroed = a.zero_at[a.zero_at >= 0]
    np.testing.assert_array_equal(np.sort(zeroed), np.flatnonzero(~a.direct))
    np.testing.assert_array_equal(np.flatnonzero(a.zero_at >= 0), np.sort(start[~a.direct]))
