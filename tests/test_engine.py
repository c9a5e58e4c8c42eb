"""The derivative engine: exact Riemannian Jacobians/Hessians of residuals of group elements.

Every residual of the paper (LGVI eq. 30–35/60, pivot/axis constraints eq. 44–45, kinematic
chain eq. 36–40, costs eq. 57/59) and functions on SO(4), SL(3) and product manifolds are checked
against central finite differences along the exact retraction ``X exp(tξ)``; the diagnostic
itself is shown to fail on wrong derivatives. Then batching, sparsity, JIT caching and input
validation.
"""

from __future__ import annotations

import ctypes
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass

import casadi as cs
import numpy as np
import pytest

import mbplan.engine.jit as jit_module
from mbplan.dynamics import (
    axis_constraint,
    kinematic_chain,
    pivot_constraint,
    rotational_dynamics,
    rotational_kinematics,
    translational_dynamics,
    translational_kinematics,
)
from mbplan.engine import CallbackFunction, DerivativeCheck, RiemannianFunction, check_derivatives
from mbplan.engine.site_function import ORDER
from mbplan.engine.site_loop_source import SITE_CHUNK, site_loop_source
from mbplan.engine.site_table import CallsInOrder, SiteTable, bound_calls, run_site_loops
from mbplan.errors import InputError, MbplanError
from mbplan.lie import SE3, SL, SO, SO3, R
from mbplan.lie.so3 import SO3Group
from mbplan.transcription.costs import chordal_cost, quadratic_cost

TOL = 1e-6
E_Z = cs.DM([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------------------------
# Residuals written inline (paper eq. 60)
# ---------------------------------------------------------------------------------------------
def forced_translational_dynamics(v0, v1, R1, u, mass, gravity, dt):
    """Eq. 60: ``m v₁ - m v₀ - m g Δt - R₁ e_z u Δt`` (thrust along the new body z axis)."""
    return translational_dynamics(v0, v1, mass, gravity, dt, force=cs.mtimes(R1, E_Z) * u)


# ---------------------------------------------------------------------------------------------
# Random points
# ---------------------------------------------------------------------------------------------
def spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


def orthonormal_frame(rng: np.random.Generator) -> np.ndarray:
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return Q


def chain_point(group, n: int, feasible: bool):
    def sample(rng):
        Xs = {f"X{i}": group.random(rng) for i in range(n)}
        Y = np.linalg.multi_dot(list(Xs.values()))
        if not feasible:  # operating point away from the current product
            Y = Y @ group.exp(0.4 * rng.standard_normal(group.dim))
        return Xs, {"Yinv": np.linalg.inv(Y)}

    return sample


def chain_residual(group, n: int):
    def residual(Yinv, **X):
        return kinematic_chain([X[f"X{i}"] for i in range(n)], Yinv, group)

    return residual


@dataclass
class Case:
    name: str
    variables: list
    residual: Callable
    parameters: list
    sample: Callable  # rng -> (variables, parameters)

    def build(self, jit: bool = False, name: str | None = None) -> RiemannianFunction:
        return RiemannianFunction(
            name or self.name, self.variables, self.residual, self.parameters, jit=jit
        )


def _rk_sample(feasible: bool):
    def sample(rng):
        R0, F0 = SO3.random(rng), SO3.random(rng)
        R1 = R0 @ F0 if feasible else R0 @ F0 @ SO3.exp(0.7 * rng.standard_normal(3))
        return {"R0": R0, "R1": R1, "F0": F0}, {}

    return sample


def _axis_sample(rng):
    frame = orthonormal_frame(rng)
    return (
        {"R1": SO3.random(rng), "R2": SO3.random(rng)},
        {"perp1": frame[:, :2].T, "axis2": orthonormal_frame(rng)[:, 2]},
    )


def _mixed_residual(R, p, T, Q, A, C):
    """A residual coupling SO(3), R³, SE(3), SO(4) and SL(3) variables (product manifold)."""
    Rt, t = T[:3, :3], T[:3, 3]
    return cs.vertcat(
        cs.mtimes([R, Rt, p]) + t,
        cs.trace(cs.mtimes([Q, C, Q.T, C])) * p[0],
        cs.vec(cs.mtimes([A, R, cs.inv(A)])),
    )


CASES = [
    Case(
        "rotational_kinematics",
        [("R0", SO3), ("R1", SO3), ("F0", SO3)],
        rotational_kinematics,
        [],
        _rk_sample(feasible=False),
    ),
    Case(
        "rotational_kinematics_feasible",
        [("R0", SO3), ("R1", SO3), ("F0", SO3)],
        rotational_kinematics,
        [],
        _rk_sample(feasible=True),
    ),
    Case(
        "translational_kinematics",
        [("p0", R(3)), ("p1", R(3)), ("v0", R(3))],
        translational_kinematics,
        [("dt", 1)],
        lambda rng: (
            {k: rng.standard_normal(3) for k in ("p0", "p1", "v0")},
            {"dt": [0.05 + rng.random()]},
        ),
    ),
    Case(
        "rotational_dynamics_torque",
        [("F0", SO3), ("F1", SO3), ("torque", R(3))],
        lambda F0, F1, torque, J, dt: rotational_dynamics(F0, F1, J, dt, torque),
        [("J", (3, 3)), ("dt", 1)],
        lambda rng: (
            {"F0": SO3.random(rng), "F1": SO3.random(rng), "torque": rng.standard_normal(3)},
            {"J": spd(rng, 3), "dt": [0.1 + rng.random()]},
        ),
    ),
    Case(
        "rotational_dynamics",
        [("F0", SO3), ("F1", SO3)],
        lambda F0, F1, J, dt: rotational_dynamics(F0, F1, J, dt),
        [("J", (3, 3)), ("dt", 1)],
        lambda rng: (
            {"F0": SO3.random(rng), "F1": SO3.random(rng)},
            {"J": spd(rng, 3), "dt": [0.1]},
        ),
    ),
    Case(
        "translational_dynamics_thrust",
        [("v0", R(3)), ("v1", R(3)), ("R1", SO3), ("u", R(1))],
        forced_translational_dynamics,
        [("mass", 1), ("gravity", 3), ("dt", 1)],
        lambda rng: (
            {
                "v0": rng.standard_normal(3),
                "v1": rng.standard_normal(3),
                "R1": SO3.random(rng),
                "u": rng.standard_normal(1),
            },
            {"mass": [0.5 + rng.random()], "gravity": [0.0, 0.0, -9.81], "dt": [0.1]},
        ),
    ),
    Case(
        "pivot_constraint",
        [("R1", SO3), ("p1", R(3)), ("R2", SO3), ("p2", R(3))],
        pivot_constraint,
        [("r1", 3), ("r2", 3)],
        lambda rng: (
            {"R1": SO3.random(rng), "p1": rng.standard_normal(3)}
            | {"R2": SO3.random(rng), "p2": rng.standard_normal(3)},
            {"r1": rng.standard_normal(3), "r2": rng.standard_normal(3)},
        ),
    ),
    Case(
        "axis_constraint",
        [("R1", SO3), ("R2", SO3)],
        axis_constraint,
        [("perp1", (2, 3)), ("axis2", 3)],
        _axis_sample,
    ),
    Case(
        "chordal_cost",
        [("R", SO3)],
        chordal_cost,
        [("R_d", (3, 3)), ("W", (3, 3))],
        lambda rng: ({"R": SO3.random(rng)}, {"R_d": SO3.random(rng), "W": spd(rng, 3)}),
    ),
    Case(
        "quadratic_cost",
        [("x", R(3))],
        quadratic_cost,
        [("x_d", 3), ("W", (3, 3))],
        lambda rng: (
            {"x": rng.standard_normal(3)},
            {"x_d": rng.standard_normal(3), "W": spd(rng, 3)},
        ),
    ),
    Case(
        "so4_function",
        [("A", SO(4)), ("B", SO(4))],
        lambda A, B, C: cs.vertcat(cs.vec(cs.mtimes([A, C, B.T])), cs.trace(cs.mtimes([A, C, A]))),
        [("C", (4, 4))],
        lambda rng: (
            {"A": SO(4).random(rng), "B": SO(4).random(rng)},
            {"C": rng.standard_normal((4, 4))},
        ),
    ),
    Case(
        "sl3_function",
        [("A", SL(3)), ("B", SL(3))],
        lambda A, B: cs.vertcat(cs.vec(cs.mtimes([A, B, A])), cs.trace(cs.mtimes(cs.inv(A), B))),
        [],
        lambda rng: ({"A": SL(3).random(rng, 0.4), "B": SL(3).random(rng, 0.4)}, {}),
    ),
    Case(
        "product_manifold",
        [("R", SO3), ("p", R(3)), ("T", SE3), ("Q", SO(4)), ("A", SL(3))],
        _mixed_residual,
        [("C", (4, 4))],
        lambda rng: (
            {"R": SO3.random(rng), "p": rng.standard_normal(3), "T": SE3.random(rng)}
            | {"Q": SO(4).random(rng), "A": SL(3).random(rng, 0.3)},
            {"C": rng.standard_normal((4, 4))},
        ),
    ),
]
for _n in (2, 3, 4):
    for _feasible in (True, False):
        CASES.append(
            Case(
                f"kinematic_chain_so3_n{_n}{'' if _feasible else '_off'}",
                [(f"X{i}", SO3) for i in range(_n)],
                chain_residual(SO3, _n),
                [("Yinv", (3, 3))],
                chain_point(SO3, _n, _feasible),
            )
        )
for _n in (2, 3):
    for _feasible in (True, False):
        CASES.append(
            Case(
                f"kinematic_chain_se3_n{_n}{'' if _feasible else '_off'}",
                [(f"X{i}", SE3) for i in range(_n)],
                chain_residual(SE3, _n),
                [("Yinv", (4, 4))],
                chain_point(SE3, _n, _feasible),
            )
        )
CASE = {c.name: c for c in CASES}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_derivatives_match_finite_differences(case):
    f = case.build()
    rng = np.random.default_rng(sum(map(ord, case.name)))
    for _ in range(3):
        variables, parameters = case.sample(rng)
        check = check_derivatives(f, variables, parameters, rng=rng)
        assert check.ok(TOL), (case.name, check)
        assert check.jacobian_error <= TOL and check.hessian_error <= TOL


# ---------------------------------------------------------------------------------------------
# The diagnostic can fail
# ---------------------------------------------------------------------------------------------
class Corrupted:
    """Delegates to a RiemannianFunction but perturbs one Jacobian or Hessian nonzero."""

    def __init__(self, f: RiemannianFunction, which: str, index: int, amount: float) -> None:
        self._f, self._which, self._index, self._amount = f, which, index, amount

    def __getattr__(self, name):
        return getattr(self._f, name)

    def hessian(self, variables, parameters, multipliers):
        r, j, h = self._f.hessian(variables, parameters, multipliers)
        if self._which == "jacobian":
            j = j.copy()
            j[:, self._index] += self._amount
        else:
            h = h.copy()
            h[:, self._index] += self._amount
        return r, j, h


class LeftRetraction:
    """Delegates to a RiemannianFunction but finite-differences along ``exp(ξ) X``."""

    def __init__(self, f: RiemannianFunction) -> None:
        self._f = f

    def __getattr__(self, name):
        return getattr(self._f, name)

    def retract(self, variables, xi):
        out = dict(variables)
        for s in self._f.variables:
            X = np.asarray(variables[s.name], dtype=float)
            out[s.name] = s.group.compose(s.group.exp(xi[..., s.tangent]), X)
        return out


class FirstOrderSO3(SO3Group):
    """SO(3) whose 'second-order' curve is only first order: ``X (I + ξ^)`` (a classic mistake)."""

    def retract_second_order(self, X, xi):
        return cs.mtimes(X, cs.DM.eye(3) + self.hat(xi))


@pytest.mark.parametrize("which", ["jacobian", "hessian"])
@pytest.mark.parametrize("amount", [1e-2, 1e-4])
def test_check_detects_a_corrupted_derivative(which, amount):
    case = CASE["rotational_dynamics_torque"]
    f = case.build()
    variables, parameters = case.sample(np.random.default_rng(1))
    lam = np.random.default_rng(0).standard_normal(f.m)
    good = check_derivatives(f, variables, parameters, lam)
    assert good.ok(TOL)
    _, j, h = f.hessian(variables, parameters, lam)
    nz = j if which == "jacobian" else h
    dense = f.dense_jacobian if which == "jacobian" else f.dense_hessian
    delta = np.zeros_like(nz)
    delta[:, nz.shape[1] // 2] = amount
    expected = np.linalg.norm(dense(delta)) / max(np.linalg.norm(dense(nz)), 1.0)

    bad = check_derivatives(
        Corrupted(f, which, nz.shape[1] // 2, amount), variables, parameters, lam
    )
    err, other = (
        (bad.jacobian_error, bad.hessian_error)
        if which == "jacobian"
        else (bad.hessian_error, bad.jacobian_error)
    )
    assert not bad.ok(TOL)
    assert err == pytest.approx(expected, rel=1e-2)
    assert other <= TOL  # the error is attributed to the right derivative


def test_check_detects_a_hessian_built_on_a_first_order_curve():
    """Dropping ξ^²/2 from the curve leaves the Jacobian right but the Hessian wrong."""
    rng = np.random.default_rng(2)
    variables, parameters = CASE["chordal_cost"].sample(rng)
    wrong = RiemannianFunction(
        "chordal_first_order",
        [("R", FirstOrderSO3())],
        chordal_cost,
        [("R_d", (3, 3)), ("W", (3, 3))],
    )
    right = CASE["chordal_cost"].build()
    bad = check_derivatives(wrong, variables, parameters)
    assert bad.jacobian_error <= TOL
    assert bad.hessian_error > 1e-2
    assert check_derivatives(right, variables, parameters).ok(TOL)


def test_check_detects_the_wrong_retraction_convention():
    """Finite differences along ``exp(ξ) X`` do not match derivatives along ``X exp(ξ)``."""
    case = CASE["pivot_constraint"]
    f = case.build()
    variables, parameters = case.sample(np.random.default_rng(3))
    bad = check_derivatives(LeftRetraction(f), variables, parameters)
    assert bad.jacobian_error > 1e-2 and bad.hessian_error > 1e-2
    assert not bad.ok()


def test_derivative_check_ok_uses_both_errors():
    assert DerivativeCheck(1e-9, 1e-9).ok()
    assert not DerivativeCheck(1e-9, 1e-3).ok()
    assert not DerivativeCheck(1e-3, 1e-9).ok()
    assert DerivativeCheck(1e-3, 1e-9).ok(tol=1e-2)


# ---------------------------------------------------------------------------------------------
# value / jacobian / hessian consistency; Taylor model along the retraction
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name",
    ["rotational_kinematics", "axis_constraint", "kinematic_chain_se3_n3_off", "sl3_function"],
)
def test_value_jacobian_hessian_agree(name):
    case = CASE[name]
    f = case.build()
    rng = np.random.default_rng(4)
    variables, parameters = case.sample(rng)
    r0 = f.value(variables, parameters)
    r1, j1 = f.jacobian(variables, parameters)
    lam = rng.standard_normal(f.m)
    r2, j2, h2 = f.hessian(variables, parameters, lam)
    assert r0.shape == (1, f.m) and j1.shape == (1, f.jac_nnz) and h2.shape == (1, f.hess_nnz)
    np.testing.assert_array_equal(r0, r1)
    np.testing.assert_array_equal(r0, r2)
    np.testing.assert_array_equal(j1, j2)
    # The Hessian of λᵀr is linear in λ: H(λ) = Σ λ_i H(e_i), evaluated as m knots at once.
    _, j_e, h_e = f.hessian(variables, parameters, np.eye(f.m))
    assert h_e.shape == (f.m, f.hess_nnz)
    np.testing.assert_allclose(lam @ h_e, h2[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(j_e, np.repeat(j1, f.m, axis=0))

    # Second-order Taylor model along X exp(tξ): remainder is O(t³).
    xi = rng.standard_normal(f.n)
    J = f.dense_jacobian(j1)[0]
    H = f.dense_hessian(h2)[0]

    def remainder(t):
        moved = f.retract(variables, t * xi)
        exact = f.value(moved, parameters)[0] @ lam
        model = r0[0] @ lam + t * lam @ J @ xi + 0.5 * t * t * xi @ H @ xi
        return abs(exact - model)

    ratio = remainder(5e-3) / remainder(1e-2)
    assert 0.08 < ratio < 0.17, ratio  # 1/8 for a cubic remainder


# ---------------------------------------------------------------------------------------------
# Batched evaluation over K knots
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["rotational_dynamics_torque", "pivot_constraint", "so4_function"])
def test_batched_evaluation_equals_single_evaluations(name):
    case = CASE[name]
    f = case.build()
    rng = np.random.default_rng(5)
    K = 5
    points = [case.sample(rng) for _ in range(K)]
    stack = {
        s.name: np.stack([np.asarray(pt[0][s.name], float) for pt in points]) for s in f.variables
    }
    pstack = {
        s.name: np.stack([np.asarray(pt[1][s.name], float) for pt in points]) for s in f.parameters
    }
    lam = rng.standard_normal((K, f.m))
    rb = f.value(stack, pstack)
    _, jb = f.jacobian(stack, pstack)
    _, _, hb = f.hessian(stack, pstack, lam)
    assert rb.shape == (K, f.m) and jb.shape == (K, f.jac_nnz) and hb.shape == (K, f.hess_nnz)
    for k, (v, p) in enumerate(points):
        r, j, h = f.hessian(v, p, lam[k])
        np.testing.assert_allclose(rb[k], r[0], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(jb[k], j[0], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(hb[k], h[0], rtol=1e-13, atol=1e-13)

    # Unbatched parameters and a single multiplier vector broadcast over the knots.
    p_single = points[0][1]
    _, jb1, hb1 = f.hessian(stack, p_single, lam[0])
    for k in range(K):
        _, j, h = f.hessian(points[k][0], p_single, lam[0])
        np.testing.assert_allclose(jb1[k], j[0], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(hb1[k], h[0], rtol=1e-13, atol=1e-13)
    # Repeated calls (cached mapped functions and buffers) return fresh, equal results.
    again = f.value(stack, pstack)
    assert again is not rb
    np.testing.assert_array_equal(again, rb)


# ---------------------------------------------------------------------------------------------
# Sparsity: fixed pattern, dense views
# ---------------------------------------------------------------------------------------------
def fd_jacobian(f: RiemannianFunction, variables, parameters, h: float = 1e-6) -> np.ndarray:
    eye = np.eye(f.n)
    tiled = {
        s.name: np.broadcast_to(np.asarray(variables[s.name], float), (2 * f.n, *s.shape))
        for s in f.variables
    }
    r = f.value(f.retract(tiled, np.concatenate([h * eye, -h * eye])), parameters)
    return (r[: f.n] - r[f.n :]).T / (2 * h)


def test_sparsity_pattern_is_fixed_and_structural():
    case = CASE["rotational_kinematics"]
    f, g = case.build(), case.build(name="rk_again")
    for a, b in [
        (f.jac_rows, g.jac_rows),
        (f.jac_cols, g.jac_cols),
        (f.hess_rows, g.hess_rows),
        (f.hess_cols, g.hess_cols),
    ]:
        np.testing.assert_array_equal(a, b)
    assert np.all(f.hess_rows >= f.hess_cols)  # lower triangle
    pattern = set(zip(f.jac_rows.tolist(), f.jac_cols.tolist(), strict=True))
    assert len(pattern) == f.jac_nnz  # no duplicates
    # At the identity many entries vanish, but the number of returned nonzeros does not change.
    identity = {"R0": np.eye(3), "R1": np.eye(3), "F0": np.eye(3)}
    _, j_id, h_id = f.hessian(identity, {}, np.ones(3))
    assert j_id.shape == (1, f.jac_nnz) and h_id.shape == (1, f.hess_nnz)
    rng = np.random.default_rng(6)
    for variables, parameters in [(identity, {})] + [case.sample(rng) for _ in range(2)]:
        J_fd = fd_jacobian(f, variables, parameters)
        outside = np.ones_like(J_fd, dtype=bool)
        outside[f.jac_rows, f.jac_cols] = False
        assert np.all(np.abs(J_fd[outside]) < 1e-8)


def test_translational_kinematics_pattern_and_values():
    f = CASE["translational_kinematics"].build()
    dt = 0.3
    variables = {"p0": [1.0, 2.0, 3.0], "p1": [0.0, 0.0, 0.0], "v0": [4.0, 5.0, 6.0]}
    r, j = f.jacobian(variables, {"dt": [dt]})
    np.testing.assert_allclose(r[0], [-1 - 1.2, -2 - 1.5, -3 - 1.8])
    I3 = np.eye(3)
    np.testing.assert_allclose(f.dense_jacobian(j)[0], np.hstack([-I3, I3, -dt * I3]))
    assert f.jac_nnz == 9 and f.hess_nnz == 0
    _, _, h = f.hessian(variables, {"dt": [dt]}, np.ones(3))
    assert h.shape == (1, 0)
    np.testing.assert_array_equal(f.dense_hessian(h)[0], np.zeros((9, 9)))


def test_constraint_hessian_block_structure():
    """Pivot: no coupling between the two bodies nor any position term; axis: coupled."""
    pivot = CASE["pivot_constraint"].build()
    block = np.zeros((pivot.n, pivot.n), dtype=bool)
    block[pivot.hess_rows, pivot.hess_cols] = True
    R1, p1, R2, p2 = (s.tangent for s in pivot.variables)
    assert block[R1, R1].any() and block[R2, R2].any()
    assert not block[R2, R1].any()
    assert (
        not block[p1].any()
        and not block[:, p1].any()
        and not block[p2].any()
        and not block[:, p2].any()
    )
    assert set(pivot.jac_cols.tolist()) == set(range(pivot.n))

    axis = CASE["axis_constraint"].build()
    block = np.zeros((axis.n, axis.n), dtype=bool)
    block[axis.hess_rows, axis.hess_cols] = True
    assert block[3:, :3].any()  # ∂²/∂ξ₂∂ξ₁ ≠ 0


def test_dense_views_scatter_the_nonzeros():
    case = CASE["so4_function"]
    f = case.build()
    rng = np.random.default_rng(8)
    K = 3
    pts = [case.sample(rng) for _ in range(K)]
    stack = {s.name: np.stack([pt[0][s.name] for pt in pts]) for s in f.variables}
    _, j, h = f.hessian(stack, pts[0][1], rng.standard_normal(f.m))
    Jd, Hd = f.dense_jacobian(j), f.dense_hessian(h)
    assert Jd.shape == (K, f.m, f.n) and Hd.shape == (K, f.n, f.n)
    np.testing.assert_array_equal(Jd[:, f.jac_rows, f.jac_cols], j)
    np.testing.assert_array_equal(Hd[:, f.hess_rows, f.hess_cols], h)
    np.testing.assert_array_equal(Hd, np.swapaxes(Hd, 1, 2))
    zero = np.ones((f.m, f.n), dtype=bool)
    zero[f.jac_rows, f.jac_cols] = False
    assert np.all(Jd[:, zero] == 0)
    for k in range(K):
        np.testing.assert_allclose(Jd[k], fd_jacobian(f, pts[k][0], pts[0][1]), atol=1e-7)


# ---------------------------------------------------------------------------------------------
# JIT compilation and the on-disk cache
# ---------------------------------------------------------------------------------------------
@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="no C compiler")
def test_jit_matches_interpreted_and_reuses_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path))
    case = CASE["rotational_dynamics_torque"]
    interpreted = case.build(name="jit_probe")
    compilations = []
    real_run = jit_module.subprocess.run

    def counting_run(cmd, *args, **kwargs):
        compilations.append(cmd)
        return real_run(cmd, *args, **kwargs)

    monkeypatch.setattr(jit_module.subprocess, "run", counting_run)
    compiled = case.build(jit=True, name="jit_probe")
    assert len(compilations) == 3  # value, jacobian, hessian
    rng = np.random.default_rng(9)
    pts = [case.sample(rng) for _ in range(4)]
    stack = {s.name: np.stack([pt[0][s.name] for pt in pts]) for s in interpreted.variables}
    params = pts[0][1]
    lam = rng.standard_normal((4, interpreted.m))
    for a, b in zip(
        compiled.hessian(stack, params, lam), interpreted.hessian(stack, params, lam), strict=True
    ):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(
        compiled.value(stack, params), interpreted.value(stack, params), rtol=1e-13, atol=1e-13
    )
    libs = sorted(tmp_path.glob("*.so"))
    assert len(libs) == 3, libs  # value, jacobian, hessian
    assert not list(tmp_path.glob("*.tmp"))
    stamps = {p: p.stat().st_mtime_ns for p in libs}

    def no_compiler(*args, **kwargs):
        raise AssertionError(f"compiler invoked: {args}")

    monkeypatch.setattr(jit_module.subprocess, "run", no_compiler)
    again = case.build(jit=True, name="jit_probe")
    assert sorted(tmp_path.glob("*.so")) == libs
    assert {p: p.stat().st_mtime_ns for p in libs} == stamps
    for a, b in zip(
        again.hessian(stack, params, lam), compiled.hessian(stack, params, lam), strict=True
    ):
        np.testing.assert_array_equal(a, b)
    # A different expression under the same name is a cache miss, compiled to its own library
    # and loaded next to the first one without symbol clashes.
    monkeypatch.setattr(jit_module.subprocess, "run", counting_run)
    doubled = RiemannianFunction(
        "jit_probe",
        case.variables,
        lambda F0, F1, torque, J, dt: 2 * rotational_dynamics(F0, F1, J, dt, torque),
        case.parameters,
        jit=True,
    )
    assert len(compilations) == 6
    assert len(list(tmp_path.glob("*.so"))) == 6
    np.testing.assert_allclose(
        doubled.value(stack, params), 2 * compiled.value(stack, params), rtol=1e-14
    )
    np.testing.assert_allclose(compiled.value(stack, params), interpreted.value(stack, params))


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="no C compiler")
def test_bound_calls_equal_the_mapped_evaluation(tmp_path, monkeypatch):
    """``bind`` (compiled: one C loop over the sites; interpreted: a CasADi buffer) gives the
    mapped evaluation bit for bit, and reads inputs refilled in place."""
    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path))
    case = CASE["rotational_dynamics_torque"]
    rng = np.random.default_rng(11)
    for fn in (case.build(name="bind_probe"), case.build(jit=True, name="bind_probe")):
        z, p, lam = (np.empty((5, width)) for width in (fn.nz, fn.np, fn.m))
        outs = {
            kind: [np.empty((5, w)) for w in (fn.m, fn.jac_nnz, fn.hess_nnz)[:n]]
            for kind, n in (("value", 1), ("jacobian", 2), ("hessian", 3))
        }
        calls = {k: fn.bind(k, [z, p, lam][: 2 + (k == "hessian")], o) for k, o in outs.items()}
        for _ in range(2):
            pts = [case.sample(rng) for _ in range(5)]
            variables = {s.name: np.stack([pt[0][s.name] for pt in pts]) for s in fn.variables}
            params = {s.name: np.stack([pt[1][s.name] for pt in pts]) for s in fn.parameters}
            z[...], p[...] = (
                fn.pack(fn.variables, variables, fn.nz, "variables"),
                fn.pack(fn.parameters, params, fn.np, "parameters"),
            )
            lam[...] = rng.standard_normal(lam.shape)
            for call in calls.values():
                call()
            expected = {
                "value": [fn.value(variables, params)],
                "jacobian": list(fn.jacobian(variables, params)),
                "hessian": list(fn.hessian(variables, params, lam)),
            }
            for kind, arrays in outs.items():
                for a, b in zip(arrays, expected[kind], strict=True):
                    np.testing.assert_array_equal(a, b)
    loop = fn._loops["value"]
    with pytest.raises(InputError, match="shape"):
        loop.bind([z[:, :-1], p], outs["value"])
    with pytest.raises(InputError, match="C-ordered"):
        loop.bind([np.asfortranarray(z), p], outs["value"])
    with pytest.raises(InputError, match="2 inputs expected, got 1"):
        loop.bind([z], outs["value"])
    read_only = np.empty_like(outs["value"][0])
    read_only.setflags(write=False)
    with pytest.raises(InputError, match="output arrays must be writeable"):
        loop.bind([z, p], [read_only])
    for either in (case.build(name="bind_probe"), fn):  # the function's bind, both paths
        with pytest.raises(InputError, match="output arrays must be writeable"):
            either.bind("value", [z, p], [read_only])
        with pytest.raises(InputError, match="shape"):
            either.bind("value", [np.empty((5, fn.nz - 1)), p], outs["value"])
        no_sites = [np.empty((0, w)) for w in (fn.nz, fn.np, fn.m)]  # z, p, λ
        no_outputs = [np.empty((0, w)) for w in (fn.m, fn.jac_nnz, fn.hess_nnz)]
        either.bind("hessian", no_sites, no_outputs)()  # no sites: nothing to evaluate
    # the compiled caller's view (table_row): the inputs' addresses, then the outputs'
    bound = loop.bind([z, p], outs["value"])  # owns the address array read below
    entry, sites, args, res = bound.table_row()
    assert (entry, sites) == (loop.entry_point, 5)
    pointers = ctypes.c_uint64 * 2
    assert list(pointers.from_address(args)) == [z.ctypes.data, p.ctypes.data]
    assert list((ctypes.c_uint64 * 1).from_address(res)) == [outs["value"][0].ctypes.data]
    assert res == args + 2 * ctypes.sizeof(ctypes.c_uint64)


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="no C compiler")
def test_site_table_runs_the_bound_loops_and_reports_a_failure(tmp_path, monkeypatch):
    """One compiled pass over a table of bound site loops writes what their own calls write;
    the first loop that fails is reported by its index and named by its error; a call that is
    not a compiled site loop gives no table."""
    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path))
    case = CASE["rotational_dynamics_torque"]
    fn = case.build(jit=True, name="table_probe")
    rng = np.random.default_rng(5)
    z, p, lam = (rng.standard_normal((4, width)) for width in (fn.nz, fn.np, fn.m))
    widths = {"value": (fn.m,), "jacobian": (fn.m, fn.jac_nnz)}
    widths["hessian"] = (fn.m, fn.jac_nnz, fn.hess_nnz)
    outs = {kind: [np.zeros((4, w)) for w in ws] for kind, ws in widths.items()}
    calls = [fn.bind(k, [z, p, lam][: 2 + (k == "hessian")], outs[k]) for k in widths]
    for call in calls:
        call()
    expected = [a.copy() for arrays in outs.values() for a in arrays]
    for arrays in outs.values():
        for a in arrays:
            a[...] = np.nan
    table = bound_calls(calls)
    assert isinstance(table, SiteTable) and not table.rows.flags.writeable
    table()
    got = [a for arrays in outs.values() for a in arrays]
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_array_equal(a, b)
    # a failing second loop: reported by its index, the first loop ran, the third did not
    loop_type = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p)
    failing = loop_type(lambda sites, args, res: 1)
    rows = table.rows.copy()
    rows[1, 0] = ctypes.cast(failing, ctypes.c_void_p).value
    for a in got:
        a[...] = np.nan
    assert run_site_loops(rows) == 1
    np.testing.assert_array_equal(outs["value"][0], expected[0])
    assert np.isnan(outs["hessian"][2]).all()
    table.rows = rows
    with pytest.raises(MbplanError, match="table_probe_jacobian: compiled evaluation failed"):
        table()
    interpreted = case.build(name="table_probe")
    # with a call that is not a compiled loop: the loops in a table, that call on its own
    plain_out = np.zeros((4, fn.m))
    plain = interpreted.bind("value", [z, p], [plain_out])
    mixed = bound_calls([plain, calls[1], calls[2]])
    assert isinstance(mixed, CallsInOrder) and mixed.calls[1:] == (plain,)
    assert isinstance(mixed.calls[0], SiteTable) and mixed.calls[0].rows.shape == (2, 4)
    mixed()
    np.testing.assert_allclose(plain_out, expected[0], rtol=1e-14)
    assert not any(isinstance(c, SiteTable) for c in bound_calls([plain]).calls)


def _site_loop_of(fn: cs.Function, folder) -> str:
    """The ``<name>_sites`` source the JIT appends to ``fn``'s generated C."""
    return jit_module._generate(fn, folder).read_text().split(f"\nint {fn.name()}_sites(")[1]


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="no C compiler")
@pytest.mark.parametrize("vectorized", [True, False])
def test_site_loops_in_chunks_equal_the_interpreted_evaluation(tmp_path, monkeypatch, vectorized):
    """Straight-line arithmetic gets the vectorized site loop (chunks of ``SITE_CHUNK`` sites, one
    SIMD lane per site), a body with another call (``sin``) the scalar one; both equal the
    interpreted evaluation at every count of sites, full and partial chunks, and write no row
    past the last site."""
    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path))
    case = CASE["rotational_dynamics_torque"]
    if vectorized:
        residual = case.residual
    else:

        def residual(F0, F1, torque, J, dt):
            return case.residual(F0, F1, cs.sin(torque), J, dt)

    name = f"chunk_probe_{vectorized}"
    interpreted = RiemannianFunction(name, case.variables, residual, case.parameters)
    compiled = RiemannianFunction(name, case.variables, residual, case.parameters, jit=True)
    source = _site_loop_of(interpreted._functions["hessian"], tmp_path)
    assert ("#pragma omp simd" in source) == vectorized
    rng = np.random.default_rng(3)
    for K in (0, 1, SITE_CHUNK - 1, SITE_CHUNK, SITE_CHUNK + 1, 2 * SITE_CHUNK + 3):
        pts = [case.sample(rng) for _ in range(K)]
        z = np.zeros((K, compiled.nz))
        p = np.zeros((K, compiled.np))
        if K:
            v = {s.name: np.stack([pt[0][s.name] for pt in pts]) for s in compiled.variables}
            q = {s.name: np.stack([pt[1][s.name] for pt in pts]) for s in compiled.parameters}
            z = compiled.pack(compiled.variables, v, compiled.nz, "variables")
            p = compiled.pack(compiled.parameters, q, compiled.np, "parameters")
        lam = rng.standard_normal((K, compiled.m))
        widths = (compiled.m, compiled.jac_nnz, compiled.hess_nnz)
        for kind, order in ORDER.items():
            inputs = [z, p, lam][: 2 + (kind == "hessian")]
            padded = [np.full((K + 2, w), np.nan) for w in widths[: order + 1]]
            compiled.bind(kind, inputs, [a[:K] for a in padded])()
            expected = interpreted.call_packed(kind, inputs)
            if K:  # and CasADi's map of the same compiled function (its scalar code)
                scalar = compiled._functions[kind].map(K)(*(a.T for a in inputs))
                scalar = [np.asarray(scalar).T] if order == 0 else [np.asarray(o).T for o in scalar]
            for i, (a, b) in enumerate(zip(padded, expected, strict=True)):
                np.testing.assert_allclose(a[:K], b, rtol=1e-13, atol=1e-13)
                assert np.isnan(a[K:]).all()
                if K:
                    np.testing.assert_allclose(a[:K], scalar[i], rtol=1e-13, atol=1e-13)


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="no C compiler")
def test_vectorized_site_loop_of_branches_constants_and_nan(tmp_path):
    """The vectorized loop of a body with CasADi's conditionals (``if_else``), comparisons,
    logic, ``inf``, ``sqrt``, ``fabs`` and squares, and an output without entries, equals
    CasADi's evaluation (NaN where it gives NaN) at full and partial chunks, NaN inputs
    included."""
    x, p = cs.SX.sym("x", 3), cs.SX.sym("p", 2)
    out = cs.vertcat(
        cs.if_else(x[0] > p[0], x[1] ** 2 + x[2] ** 2, cs.sqrt(x[0] ** 2 + 1)),
        (x[0] < x[1]) + cs.logic_and(x[1] > 0, x[2] < 0) + cs.logic_not(x[0] >= 0),
        x[0] * cs.inf + cs.fabs(x[1]),
        cs.if_else(x[2] != x[2], 5, x[2] / p[1]),
    )
    fn = cs.Function("branch_probe", [x, p], [out, cs.SX(2, 1)])
    src = jit_module._generate(fn, tmp_path)
    assert "#pragma omp simd" in src.read_text().split("\nint branch_probe_sites(")[1]
    jit_module._build(jit_module.compiler(), jit_module.DEFAULT_FLAGS, src, tmp_path / "b.so")
    loop = jit_module.SiteLoop(fn, tmp_path / "b.so")
    rng = np.random.default_rng(4)
    for K in (1, SITE_CHUNK - 1, SITE_CHUNK, 2 * SITE_CHUNK + 3):
        X, P = rng.standard_normal((K, 3)), rng.standard_normal((K, 2))
        X[K // 2, 2], X[K - 1, 0] = np.nan, 0.0
        got = loop.evaluate([X, P])
        expected = np.asarray(fn.map(K)(X.T, P.T)[0]).T
        assert got[1].shape == (K, 0)
        np.testing.assert_allclose(got[0], expected, rtol=1e-15, atol=0, equal_nan=True)


@pytest.mark.parametrize(
    "body, why",
    [
        ("  a0=arg[0]? arg[0][0] : 0;\n  if (res[0]!=0) res[0][0]=sin(a0);", "another call"),
        ("  a0=arg[0]? arg[0][0] : 0;\n  if (res[0]!=0) res[0][1]=a0;", "an entry not written"),
        ("  a0=arg[0]? arg[0][0] : 0;\n  w[0]=a0;\n  if (res[0]!=0) res[0][0]=a0;", "work vector"),
        ("  a0=arg[0]? arg[0][1] : 0;\n  if (res[0]!=0) res[0][0]=a0;", "no such argument entry"),
        ("  a0=arg[0]? arg[0][0] : 0;\n  if (res[0]!=0) res[0][0]=(k+a0);", "a name not local"),
        ("  casadi_int i0;\n  a0=arg[0]? arg[0][0] : 0;\n  if (res[0]!=0) res[0][0]=a0;", "an int"),
    ],
)
def test_site_loop_falls_back_to_scalar_on_anything_else(body, why):
    """A body that is not straight-line arithmetic writing every result entry once gets the
    scalar loop (CasADi's function per site)."""
    x = cs.SX.sym("x")
    fn = cs.Function("fallback_probe", [x], [x])
    source = (
        "static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, "
        f"casadi_real* w, int mem) {{\n  casadi_real a0;\n{body}\n  return 0;\n}}\n"
    )
    loop = site_loop_source(fn, source)
    assert "#pragma omp simd" not in loop and "fallback_probe(a, r, iw, w, 0)" in loop, why
    good = source.replace(body, "  a0=arg[0]? arg[0][0] : 0;\n  if (res[0]!=0) res[0][0]=a0;")
    assert "#pragma omp simd" in site_loop_source(fn, good)


@pytest.mark.parametrize("op", [cs.fmax, cs.atan2, lambda a, b: cs.sin(a) * b])
def test_site_loop_of_casadi_calls_it_cannot_inline_is_scalar(tmp_path, op):
    """CasADi's own code with a call other than its square, ``fabs`` and ``sqrt`` (``fmax``,
    ``atan2``, ``sin``) gets the scalar loop."""
    x = cs.SX.sym("x", 2)
    fn = cs.Function("call_probe", [x], [op(x[0], x[1]) + x[0] ** 2])
    assert "#pragma omp simd" not in _site_loop_of(fn, tmp_path)


# ---------------------------------------------------------------------------------------------
# Input validation
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rk():
    return CASE["rotational_dynamics_torque"].build()


@pytest.fixture(scope="module")
def rk_point():
    return CASE["rotational_dynamics_torque"].sample(np.random.default_rng(10))


def _replace(d, **kw):
    out = dict(d)
    out.update(kw)
    return out


def _drop(d, key):
    return {k: v for k, v in d.items() if k != key}


BAD_EVALUATIONS = [
    ("missing variable", lambda v, p: (_drop(v, "F1"), p, None), r"missing \['F1'\]"),
    (
        "unexpected variable",
        lambda v, p: (_replace(v, X=np.eye(3)), p, None),
        r"unexpected \['X'\]",
    ),
    ("missing parameter", lambda v, p: (v, _drop(p, "dt"), None), r"parameters missing \['dt'\]"),
    ("no parameters", lambda v, p: (v, None, None), r"parameters missing \['J', 'dt'\]"),
    ("wrong shape", lambda v, p: (_replace(v, F0=np.eye(2)), p, None), r"'F0' must have shape"),
    (
        "wrong vector length",
        lambda v, p: (_replace(v, torque=np.zeros(4)), p, None),
        r"'torque' must have shape",
    ),
    (
        "wrong parameter shape",
        lambda v, p: (v, _replace(p, J=np.eye(4)), None),
        r"'J' must have shape",
    ),
    (
        "NaN variable",
        lambda v, p: (_replace(v, torque=[0.0, np.nan, 0.0]), p, None),
        r"'torque' contains NaN",
    ),
    (
        "inf parameter",
        lambda v, p: (v, _replace(p, dt=[np.inf]), None),
        r"'dt' contains NaN or inf",
    ),
    (
        "knot count mismatch",
        lambda v, p: (
            _replace(v, F0=np.stack([np.eye(3)] * 3), F1=np.stack([np.eye(3)] * 4)),
            p,
            None,
        ),
        r"'F1' has 4 knots, expected 3",
    ),
    ("multiplier length", lambda v, p: (v, p, np.ones(4)), r"multipliers must have shape \(K, 3\)"),
    ("multiplier ndim", lambda v, p: (v, p, np.ones((1, 1, 3))), r"multipliers must have shape"),
    (
        "NaN multiplier",
        lambda v, p: (v, p, np.array([1.0, np.nan, 0.0])),
        r"multipliers contain NaN",
    ),
    (
        "multiplier knots vs variables",
        lambda v, p: (_replace(v, F0=np.stack([np.eye(3)] * 3)), p, np.ones((2, 3))),
        r"multipliers have 2 knots, expected 1 or 3",
    ),
    (
        "NaN variable given once, at no sites",
        lambda v, p: (_replace(v, torque=[np.nan, 0.0, 0.0]), p, np.zeros((0, 3))),
        r"'torque' contains NaN",
    ),
    (
        "parameter knots vs variables",
        lambda v, p: (
            _replace(v, F0=np.stack([np.eye(3)] * 3)),
            _replace(p, dt=np.full((2, 1), 0.1)),
            None,
        ),
        r"'dt' has 2 knots, expected 3",
    ),
]


@pytest.mark.parametrize(
    "make, match", [b[1:] for b in BAD_EVALUATIONS], ids=[b[0] for b in BAD_EVALUATIONS]
)
def test_bad_evaluation_input_raises(rk, rk_point, make, match):
    variables, parameters, lam = make(*rk_point)
    calls = [lambda: rk.hessian(variables, parameters, lam)]
    if lam is None:  # every evaluation entry point validates
        calls = [
            lambda: rk.value(variables, parameters),
            lambda: rk.jacobian(variables, parameters),
            lambda: rk.hessian(variables, parameters, np.ones(rk.m)),
        ]
    for call in calls:
        with pytest.raises(InputError, match=match):
            call()


def test_packed_parameters_must_match_the_sites(rk, rk_point):
    variables, parameters = rk_point
    at_three = {k: np.stack([np.asarray(v)] * 3) for k, v in variables.items()}
    packed = rk.pack_parameters(parameters, 2)
    with pytest.raises(InputError, match=r"packed parameters must have shape \(1 or 3, 10\)"):
        rk.value(at_three, packed)
    with pytest.raises(InputError, match="packed parameters contain NaN"):
        rk.value(at_three, np.full((3, 10), np.nan))
    assert rk.value(at_three, rk.pack_parameters(parameters, 3)).shape == (3, rk.m)
    as_ints = rk.pack_parameters(parameters, 1).round().astype(np.int64)
    assert np.array_equal(rk.value(variables, as_ints), rk.value(variables, as_ints.astype(float)))


def _zero_site_callback() -> CallbackFunction:
    def evaluate(variables, params, lam, order):
        y = variables["y"]
        assert len(y), "the callback is called at no sites"
        r = y[:, :1] * params[:, :1]
        outs = [r, params[:, :1].copy(), np.zeros((len(y), 0))]
        return outs[: order + 1]

    return CallbackFunction("scaled", [("y", R(2))], [("a", 1)], 1, ([0], [0]), ([], []), evaluate)


@pytest.mark.parametrize("which", ["riemannian", "callback"])
def test_every_entry_point_evaluates_at_no_sites(rk, which):
    """``K = 0`` sites give empty ``(0, ·)`` outputs of the right widths on every entry point
    (CasADi has no 0-fold map; a callback is not called)."""
    if which == "riemannian":
        fn = rk
        variables = {s.name: np.zeros((0, *s.shape)) for s in rk.variables}
        parameters = {"J": np.eye(3), "dt": 0.1}
    else:
        fn = _zero_site_callback()
        variables, parameters = {"y": np.zeros((0, 2))}, {"a": 2.0}
    widths = (fn.m, fn.jac_nnz, fn.hess_nnz)
    outs = [
        [fn.value(variables, parameters)],
        list(fn.jacobian(variables, parameters)),
        list(fn.hessian(variables, parameters, np.zeros((0, fn.m)))),
    ]
    for order, got in enumerate(outs):
        assert [a.shape for a in got] == [(0, w) for w in widths[: order + 1]]
    at_one_site = {k: np.zeros((1, *v.shape[1:])) for k, v in variables.items()}
    assert fn.value(at_one_site, parameters).shape == (1, fn.m)  # the same call at one site


def test_bad_construction_raises():
    with pytest.raises(InputError, match="valid identifier"):
        RiemannianFunction("not a name", [("R", SO3)], lambda R: R)
    with pytest.raises(InputError, match="duplicate"):
        RiemannianFunction("dup", [("R", SO3)], lambda R: R, [("R", 3)])


def test_numba_cache_index_is_looked_up_until_seen(tmp_path) -> None:
    """``numba_cached``: False without an index file; once seen, True without a lookup."""
    from types import SimpleNamespace

    from mbplan.engine.jit import numba_cached

    index = tmp_path / "kernel.nbi"
    fake = SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=index)))
    assert not numba_cached(fake)
    index.write_bytes(b"")
    assert numba_cached(fake)
    index.unlink()
    assert numba_cached(fake)
    assert numba_cached(object())  # not a cached dispatcher
