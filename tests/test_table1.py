"""Closed-form expansions of Table I and eq. 40 (RIPM paper §VI) against the derivative engine.

For each residual ``r`` and a random tangent ``ξ``, substituting ``X exp(tξ) ≈ X(I + tξ^ + t²ξ^²/2)``
(and ``y + tξ`` for vectors) gives ``r(t) = r + t·first + t²·second + O(t³)``. The engine must
satisfy ``J ξ = first`` and ``½ ξᵀ H_i ξ = second_i`` with ``H_i`` its Hessian for ``λ = e_i``.

Every closed form below is derived by hand from that substitution. Where the printed Table I
differs, the printed version is kept as its own function and a test shows the disagreement:

* Row 2 (translational kinematics) prints ``ξ_{k+1}^p - ξ_k^p - ξ_k^p Δt``; the last term is
  ``ξ_k^v Δt`` (the residual is ``p_{k+1} - p_k - v_k Δt``).
* Row 3 (rotational dynamics) prints the first-order term ``I_b F_{k+1} ξ_{k+1} - I_b F_k ξ_k``
  with ``I_b = tr(I^b) I - I^b``. That holds only at ``F = I``; in general it is
  ``F_{k+1}(tr(I^b F_{k+1}) I - I^b F_{k+1}) ξ_{k+1} - (tr(I^b F_k) I - F_kᵀ I^b) ξ_k``.
  The printed second-order ``F_k`` term has the wrong sign: it is
  ``-½ (I^b F_k ξ_k^{∧2} - ξ_k^{∧2} F_kᵀ I^b)^∨`` because the residual subtracts
  ``(I^b F_k - F_kᵀ I^b)``.
* Row 5 (pivot) prints ``... - R_2(ξ_2^∧ + ½ξ_2^{∧2}) r_2 + ξ_2^p``; the sign of ``ξ_2^p`` is ``-``.
* Row 6 (axis) prints scalars times ``ξ^∧`` (garbled; read as ``-(R_1e_i)ᵀR_2 e_z^∧ ξ_2 -
  (R_2e_z)ᵀR_1 e_i^∧ ξ_1``, which is correct) and a second-order term without the mixed term
  ``(R_1 ξ_1^∧ e_i)ᵀ(R_2 ξ_2^∧ e_z)``; without it the Hessian block coupling the two bodies would
  be zero. (Read literally with ``ξ^∧`` instead of ``ξ^{∧2}`` it is not even second order.)
* Row 1 (rotational kinematics) is right at a feasible point (``Y = R_{k+1}ᵀ R_k F_k = I``, so
  ``Y⁻¹ = I``). Elsewhere it is the expansion of ``log(Y⁻¹·perturbed product)``. mbplan's residual
  is the inverse Cayley map ``cay⁻¹(Y)`` instead of ``log Y`` (equal to third order at ``Y = I``:
  the row holds for it at feasible points); off them its first-order term is the map's
  differential at ``Y`` applied to the printed row (tested below).
* Row 4 (translational dynamics) and eq. 40 (kinematic chain) are right as printed.
"""

from __future__ import annotations

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest

from mbplan.dynamics import (
    axis_constraint,
    kinematic_chain,
    pivot_constraint,
    rotational_dynamics,
    rotational_kinematics,
    translational_dynamics,
    translational_kinematics,
)
from mbplan.engine import RiemannianFunction
from mbplan.lie import SE3, SO3, R

E_X, E_Y, E_Z = np.eye(3)
N_POINTS = 4
N_DIRECTIONS = 3


def hat(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def vee(A: np.ndarray) -> np.ndarray:
    return 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])


def spd(rng: np.random.Generator) -> np.ndarray:
    A = rng.standard_normal((3, 3))
    return A @ A.T + 3 * np.eye(3)


def engine_terms(f: RiemannianFunction, variables, parameters, xi: np.ndarray):
    """``J ξ`` and ``(½ ξᵀ H_i ξ)_i`` from the engine (``H_i``: Hessian with ``λ = e_i``)."""
    _, j, h = f.hessian(variables, parameters, np.eye(f.m))
    J = f.dense_jacobian(j[:1])[0]
    H = f.dense_hessian(h)
    return J @ xi, 0.5 * np.einsum("j,ijk,k->i", xi, H, xi)


def split(f: RiemannianFunction, xi: np.ndarray) -> dict[str, np.ndarray]:
    return {s.name: xi[s.tangent] for s in f.variables}


def assert_terms(f, variables, parameters, closed_form, rng, atol=1e-11):
    """Compare the engine with ``closed_form(variables, parameters, ξ-parts) -> (first, second)``."""
    for _ in range(N_DIRECTIONS):
        xi = rng.standard_normal(f.n)
        first, second = engine_terms(f, variables, parameters, xi)
        want_first, want_second = closed_form(variables, parameters, split(f, xi))
        scale = 1.0 + np.abs(want_first).max() + np.abs(want_second).max()
        np.testing.assert_allclose(first, want_first, rtol=0, atol=atol * scale)
        np.testing.assert_allclose(second, want_second, rtol=0, atol=atol * scale)


def differs(f, variables, parameters, closed_form, rng, which: int) -> float:
    """Largest relative gap between the engine and ``closed_form``'s ``which`` term."""
    gaps = []
    for _ in range(N_DIRECTIONS):
        xi = rng.standard_normal(f.n)
        got = engine_terms(f, variables, parameters, xi)[which]
        want = closed_form(variables, parameters, split(f, xi))[which]
        gaps.append(np.abs(got - want).max() / (1.0 + np.abs(got).max()))
    return max(gaps)


# ---------------------------------------------------------------------------------------------
# Row 1: rotational kinematics log(R_{k+1}ᵀ R_k F_k) (mbplan: cay⁻¹ of the same product)
# ---------------------------------------------------------------------------------------------
def rotational_kinematics_terms(v, p, x):
    """Table I row 1 (as printed; exact at Y = I).

    Perturbed product = Y exp(-t Y⁻¹ξ_{k+1}) exp(t F_k⁻¹ ξ_k^R) exp(t ξ_k^F), then BCH:
    log(e^{ta} e^{tb} e^{tc}) = t(a+b+c) + t²/2([a,b] + [a,c] + [b,c]) + O(t³).
    """
    Y = v["R1"].T @ v["R0"] @ v["F0"]
    a = -np.linalg.inv(Y) @ x["R1"]  # Ad_{Y⁻¹} = Y⁻¹ on SO(3)
    b = v["F0"].T @ x["R0"]
    c = x["F0"]
    first = a + b + c
    second = 0.5 * (np.cross(a, b) + np.cross(a, c) + np.cross(b, c))
    return first, second


ROT_KIN = dict(variables=[("R0", SO3), ("R1", SO3), ("F0", SO3)], residual=rotational_kinematics)


def test_row1_rotational_kinematics_at_a_feasible_point():
    f = RiemannianFunction("t1_rot_kin", **ROT_KIN)
    rng = np.random.default_rng(1)
    for _ in range(N_POINTS):
        R0, F0 = SO3.random(rng), SO3.random(rng)
        variables = {"R0": R0, "R1": R0 @ F0, "F0": F0}  # R₁ᵀR₀F₀ = I
        assert np.abs(f.value(variables)).max() < 1e-14
        assert_terms(f, variables, {}, rotational_kinematics_terms, rng)


def cayley_inverse(M: np.ndarray) -> np.ndarray:
    """``cay⁻¹(M) = 2 (M - Mᵀ)^∨ / (1 + tr M)`` (``2 tan(θ/2) a`` for ``M = exp(θ a)``)."""
    return 2.0 * vee(M - M.T) / (1.0 + np.trace(M))


def test_row1_residual_is_the_log_to_third_order_with_no_root_but_the_identity():
    """mbplan's residual at ``R₁ᵀR₀F₀ = exp(θa)`` is ``2 tan(θ/2) a``: within ``θ³/12`` of the
    log near 0, and along ``(0, π)`` its norm grows strictly (no root but ``θ = 0``)."""
    f = RiemannianFunction("t1_rot_kin_cayley", **ROT_KIN)
    rng = np.random.default_rng(5)
    R0, F0 = SO3.random(rng), SO3.random(rng)
    a = rng.standard_normal(3)
    a /= np.linalg.norm(a)
    thetas = np.concatenate([[1e-3, 1e-2, 0.1], np.linspace(0.2, np.pi - 1e-3, 40)])
    norms = []
    for theta in thetas:
        Y = SO3.exp(theta * a)
        got = f.value({"R0": R0, "R1": R0 @ F0 @ Y.T, "F0": F0})[0]  # R₁ᵀR₀F₀ = Y
        np.testing.assert_allclose(got, cayley_inverse(Y), rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(got, 2.0 * np.tan(theta / 2) * a, rtol=1e-9)
        if theta <= 0.1:  # 2 tan(θ/2) - θ = θ³/12 + O(θ⁵)
            assert np.linalg.norm(got - theta * a) <= theta**3 / 12 * 1.01 + 1e-16
        norms.append(np.linalg.norm(got))
    assert norms[0] > 0 and np.all(np.diff(norms) > 0)


def test_row1_residual_equals_the_log_on_the_constraint_set():
    """At feasible points the Cayley residual and Table I's ``log(R₁ᵀR₀F₀)`` have the same
    value, Jacobian and multiplier-contracted Hessian (the engine's, for a random ``λ``); off
    the set they differ (the comparison can fail)."""
    f = RiemannianFunction("t1_rot_kin_vs_log_cayley", **ROT_KIN)
    log = RiemannianFunction(
        "t1_rot_kin_vs_log_log",
        variables=ROT_KIN["variables"],
        residual=lambda R0, R1, F0: SO3.log(cs.mtimes([R1.T, R0, F0])),
    )
    rng = np.random.default_rng(17)

    def derivatives(g, variables, lam):
        value, j, h = g.hessian(variables, {}, lam[None])
        return value[0], g.dense_jacobian(j)[0], g.dense_hessian(h)[0]

    for off in (0.0, 0.2):
        R0, F0 = SO3.random(rng), SO3.random(rng)
        R1 = R0 @ F0 @ SO3.exp(off * rng.standard_normal(3))
        variables = {"R0": R0, "R1": R1, "F0": F0}
        lam = 10.0 * rng.standard_normal(3)
        pairs = zip(derivatives(f, variables, lam), derivatives(log, variables, lam), strict=True)
        gaps = [np.abs(x - y).max() for x, y in pairs]
        if off == 0.0:
            assert max(gaps) < 1e-12, gaps
        else:
            assert min(gaps) > 1e-5, gaps


def test_row1_off_the_feasible_set_takes_the_residuals_differential():
    """At Y ≠ I the printed row expands the product (right-trivialized: ``Y exp(t ξ)``); the
    residual adds its differential at Y: ``d cay⁻¹(Y)[Y ξ^]``."""
    f = RiemannianFunction("t1_rot_kin_off", **ROT_KIN)
    rng = np.random.default_rng(11)
    R0, F0 = SO3.random(rng), SO3.random(rng)
    variables = {"R0": R0, "R1": R0 @ F0 @ SO3.exp(0.5 * rng.standard_normal(3)), "F0": F0}
    Y = variables["R1"].T @ R0 @ F0
    for _ in range(N_DIRECTIONS):
        xi = rng.standard_normal(f.n)
        first, _ = engine_terms(f, variables, {}, xi)
        printed, _ = rotational_kinematics_terms(variables, {}, split(f, xi))
        dY = Y @ hat(printed)
        scale = 1.0 + np.trace(Y)
        want = 2.0 * vee(dY - dY.T) / scale - 2.0 * vee(Y - Y.T) * np.trace(dY) / scale**2
        np.testing.assert_allclose(first, want, atol=1e-12)
        assert np.abs(first - printed).max() > 1e-3


# ---------------------------------------------------------------------------------------------
# Row 2: translational kinematics p_{k+1} - p_k - v_k Δt
# ---------------------------------------------------------------------------------------------
def translational_kinematics_terms(v, p, x):
    """Linear residual: ξ_{k+1}^p - ξ_k^p - ξ_k^v Δt, no second-order term."""
    return x["p1"] - x["p0"] - x["v0"] * p["dt"][0], np.zeros(3)


def translational_kinematics_printed(v, p, x):
    """As printed in Table I: ξ_{k+1}^p - ξ_k^p - ξ_k^p Δt (typo: ξ_k^p for ξ_k^v)."""
    return x["p1"] - x["p0"] - x["p0"] * p["dt"][0], np.zeros(3)


def test_row2_translational_kinematics():
    f = RiemannianFunction(
        "t1_trans_kin",
        [("p0", R(3)), ("p1", R(3)), ("v0", R(3))],
        translational_kinematics,
        [("dt", 1)],
    )
    rng = np.random.default_rng(2)
    for _ in range(N_POINTS):
        variables = {k: rng.standard_normal(3) for k in ("p0", "p1", "v0")}
        parameters = {"dt": [0.05 + rng.random()]}
        assert_terms(f, variables, parameters, translational_kinematics_terms, rng)
        assert differs(f, variables, parameters, translational_kinematics_printed, rng, 0) > 1e-3


# ---------------------------------------------------------------------------------------------
# Row 3: rotational dynamics (F_{k+1} I^b - I^b F_{k+1}ᵀ - (I^b F_k - F_kᵀ I^b))^∨ (- τ Δt²)
# ---------------------------------------------------------------------------------------------
def rotational_dynamics_terms(v, p, x):
    """Correct expansion. With ξ^ᵀ = -ξ^ and (ξ^²)ᵀ = ξ^²:

    F exp(tξ) J - J exp(-tξ) Fᵀ = FJ - JFᵀ + t(Fξ^J + Jξ^Fᵀ) + t²/2 (Fξ^²J - Jξ^²Fᵀ) + O(t³),
    and ``(ξ^M + Mᵀξ^)^∨ = (tr(M) I - M) ξ`` for any M gives the first-order terms.
    """
    J, dt = p["J"], p["dt"][0]
    F0, F1, x0, x1 = v["F0"], v["F1"], x["F0"], x["F1"]
    first = F1 @ (np.trace(J @ F1) * np.eye(3) - J @ F1) @ x1
    first -= (np.trace(J @ F0) * np.eye(3) - F0.T @ J) @ x0
    second = 0.5 * vee(F1 @ hat(x1) @ hat(x1) @ J - J @ hat(x1) @ hat(x1) @ F1.T)
    second -= 0.5 * vee(J @ F0 @ hat(x0) @ hat(x0) - hat(x0) @ hat(x0) @ F0.T @ J)
    if "torque" in x:
        first = first - dt**2 * x["torque"]
    return first, second


def rotational_dynamics_printed(v, p, x):
    """As printed: I_b F_{k+1} ξ_{k+1} - I_b F_k ξ_k + ½(...)_{k+1}^∨ + ½(I^b F_k ξ^2 - ξ^2 F_kᵀ I^b)^∨."""
    J = p["J"]
    Ib = np.trace(J) * np.eye(3) - J
    F0, F1, x0, x1 = v["F0"], v["F1"], x["F0"], x["F1"]
    first = Ib @ F1 @ x1 - Ib @ F0 @ x0
    second = 0.5 * vee(F1 @ hat(x1) @ hat(x1) @ J - J @ hat(x1) @ hat(x1) @ F1.T)
    second += 0.5 * vee(J @ F0 @ hat(x0) @ hat(x0) - hat(x0) @ hat(x0) @ F0.T @ J)
    return first, second


def test_row3_rotational_dynamics():
    f = RiemannianFunction(
        "t1_rot_dyn",
        [("F0", SO3), ("F1", SO3)],
        lambda F0, F1, J, dt: rotational_dynamics(F0, F1, J, dt),
        [("J", (3, 3)), ("dt", 1)],
    )
    rng = np.random.default_rng(3)
    for _ in range(N_POINTS):
        variables = {"F0": SO3.random(rng), "F1": SO3.random(rng)}
        parameters = {"J": spd(rng), "dt": [0.1]}
        assert_terms(f, variables, parameters, rotational_dynamics_terms, rng)
        # The printed first-order term only holds at F = I; the printed F_k second-order sign
        # is wrong everywhere.
        assert differs(f, variables, parameters, rotational_dynamics_printed, rng, 0) > 1e-3
        assert differs(f, variables, parameters, rotational_dynamics_printed, rng, 1) > 1e-3
        at_identity = {"F0": np.eye(3), "F1": np.eye(3)}
        assert differs(f, at_identity, parameters, rotational_dynamics_printed, rng, 0) < 1e-12
        assert differs(f, at_identity, parameters, rotational_dynamics_printed, rng, 1) > 1e-3


def test_row3_rotational_dynamics_with_torque():
    """Forced form (eq. 60): the torque adds -Δt² ξ^τ to the first-order term."""
    f = RiemannianFunction(
        "t1_rot_dyn_tau",
        [("F0", SO3), ("F1", SO3), ("torque", R(3))],
        lambda F0, F1, torque, J, dt: rotational_dynamics(F0, F1, J, dt, torque),
        [("J", (3, 3)), ("dt", 1)],
    )
    rng = np.random.default_rng(13)
    for _ in range(N_POINTS):
        variables = {"F0": SO3.random(rng), "F1": SO3.random(rng), "torque": rng.normal(size=3)}
        parameters = {"J": spd(rng), "dt": [0.05 + rng.random()]}
        assert_terms(f, variables, parameters, rotational_dynamics_terms, rng)


# ---------------------------------------------------------------------------------------------
# Row 4: translational dynamics m v_{k+1} - m v_k - m g Δt (- R_{k+1} e_z u Δt, eq. 60)
# ---------------------------------------------------------------------------------------------
def translational_dynamics_terms(v, p, x):
    """m ξ_{k+1}^v - m ξ_k^v (as printed); no second-order term."""
    m = p["mass"][0]
    return m * x["v1"] - m * x["v0"], np.zeros(3)


def thrust_dynamics_terms(v, p, x):
    """Eq. 60 force f = R_{k+1} e_z u: R(I + tξ^ + t²ξ^²/2) e_z (u + tξ^u), times -Δt."""
    first, second = translational_dynamics_terms(v, p, x)
    dt, R1, u = p["dt"][0], v["R1"], v["u"][0]
    w, du = x["R1"], x["u"][0]
    first = first - dt * (R1 @ hat(w) @ E_Z * u + R1 @ E_Z * du)
    second = second - dt * (0.5 * R1 @ hat(w) @ hat(w) @ E_Z * u + R1 @ hat(w) @ E_Z * du)
    return first, second


def test_row4_translational_dynamics():
    f = RiemannianFunction(
        "t1_trans_dyn",
        [("v0", R(3)), ("v1", R(3))],
        translational_dynamics,
        [("mass", 1), ("gravity", 3), ("dt", 1)],
    )
    rng = np.random.default_rng(4)
    for _ in range(N_POINTS):
        variables = {"v0": rng.standard_normal(3), "v1": rng.standard_normal(3)}
        parameters = {"mass": [0.5 + rng.random()], "gravity": [0, 0, -9.81], "dt": [0.1]}
        assert_terms(f, variables, parameters, translational_dynamics_terms, rng)


def test_row4_translational_dynamics_with_thrust():
    def residual(v0, v1, R1, u, mass, gravity, dt):
        thrust = cs.mtimes(R1, cs.DM(E_Z)) * u
        return translational_dynamics(v0, v1, mass, gravity, dt, force=thrust)

    f = RiemannianFunction(
        "t1_thrust",
        [("v0", R(3)), ("v1", R(3)), ("R1", SO3), ("u", R(1))],
        residual,
        [("mass", 1), ("gravity", 3), ("dt", 1)],
    )
    rng = np.random.default_rng(14)
    for _ in range(N_POINTS):
        variables = {"v0": rng.normal(size=3), "v1": rng.normal(size=3), "R1": SO3.random(rng)}
        variables["u"] = [5.0 + rng.random()]
        parameters = {"mass": [0.5 + rng.random()], "gravity": [0, 0, -9.81], "dt": [0.1]}
        assert_terms(f, variables, parameters, thrust_dynamics_terms, rng)


# ---------------------------------------------------------------------------------------------
# Row 5: pivot R_1 r_1 + p_1 - (R_2 r_2 + p_2)
# ---------------------------------------------------------------------------------------------
def pivot_terms(v, p, x):
    """R_1 ξ_1^ r_1 + ξ_1^p - R_2 ξ_2^ r_2 - ξ_2^p;  ½R_1 ξ_1^{∧2} r_1 - ½R_2 ξ_2^{∧2} r_2."""
    R1, R2, r1, r2 = v["R1"], v["R2"], p["r1"], p["r2"]
    w1, w2 = hat(x["R1"]), hat(x["R2"])
    first = R1 @ w1 @ r1 + x["p1"] - R2 @ w2 @ r2 - x["p2"]
    second = 0.5 * R1 @ w1 @ w1 @ r1 - 0.5 * R2 @ w2 @ w2 @ r2
    return first, second


def pivot_printed(v, p, x):
    """As printed: the sign of ξ_2^p is + (should be -)."""
    first, second = pivot_terms(v, p, x)
    return first + 2 * x["p2"], second


def test_row5_pivot():
    f = RiemannianFunction(
        "t1_pivot",
        [("R1", SO3), ("p1", R(3)), ("R2", SO3), ("p2", R(3))],
        pivot_constraint,
        [("r1", 3), ("r2", 3)],
    )
    rng = np.random.default_rng(5)
    for _ in range(N_POINTS):
        variables = {"R1": SO3.random(rng), "p1": rng.normal(size=3)}
        variables |= {"R2": SO3.random(rng), "p2": rng.normal(size=3)}
        parameters = {"r1": rng.normal(size=3), "r2": rng.normal(size=3)}
        assert_terms(f, variables, parameters, pivot_terms, rng)
        assert differs(f, variables, parameters, pivot_printed, rng, 0) > 1e-3


# ---------------------------------------------------------------------------------------------
# Row 6: axis (R_1 e_i)ᵀ(R_2 e_z) = 0, i = x, y
# ---------------------------------------------------------------------------------------------
def axis_terms(v, p, x):
    """First: -(R_1 e_i)ᵀ R_2 e_z^ ξ_2 - (R_2 e_z)ᵀ R_1 e_i^ ξ_1 (using ξ^ e = -e^ ξ).

    Second: ½(R_1 e_i)ᵀ R_2 ξ_2^{∧2} e_z + ½(R_2 e_z)ᵀ R_1 ξ_1^{∧2} e_i + (R_1 ξ_1^ e_i)ᵀ(R_2 ξ_2^ e_z).
    """
    R1, R2 = v["R1"], v["R2"]
    x1, x2 = x["R1"], x["R2"]
    w1, w2 = hat(x1), hat(x2)
    first, second = [], []
    for e in (E_X, E_Y):
        first.append(-(R1 @ e) @ R2 @ hat(E_Z) @ x2 - (R2 @ E_Z) @ R1 @ hat(e) @ x1)
        second.append(
            0.5 * (R1 @ e) @ (R2 @ w2 @ w2 @ E_Z)
            + 0.5 * (R2 @ E_Z) @ (R1 @ w1 @ w1 @ e)
            + (R1 @ w1 @ e) @ (R2 @ w2 @ E_Z)
        )
    return np.array(first), np.array(second)


def axis_printed(v, p, x):
    """Printed second-order term (reading its ξ^∧ as ξ^{∧2}): no mixed term."""
    first, _ = axis_terms(v, p, x)
    R1, R2 = v["R1"], v["R2"]
    w1, w2 = hat(x["R1"]), hat(x["R2"])
    second = [
        0.5 * (R1 @ e) @ (R2 @ w2 @ w2 @ E_Z) + 0.5 * (R2 @ E_Z) @ (R1 @ w1 @ w1 @ e)
        for e in (E_X, E_Y)
    ]
    return first, np.array(second)


def test_row6_axis():
    f = RiemannianFunction(
        "t1_axis",
        [("R1", SO3), ("R2", SO3)],
        axis_constraint,
        [("perp1", (2, 3)), ("axis2", 3)],
    )
    parameters = {"perp1": np.stack([E_X, E_Y]), "axis2": E_Z}
    rng = np.random.default_rng(6)
    for _ in range(N_POINTS):
        variables = {"R1": SO3.random(rng), "R2": SO3.random(rng)}
        assert_terms(f, variables, parameters, axis_terms, rng)
        assert differs(f, variables, parameters, axis_printed, rng, 1) > 1e-3
    # Also at a feasible point (shared z axis): the mixed term is still there.
    R1 = SO3.random(rng)
    variables = {"R1": R1, "R2": R1 @ SO3.exp([0.0, 0.0, 0.7])}
    assert np.abs(f.value(variables, parameters)).max() < 1e-14
    assert_terms(f, variables, parameters, axis_terms, rng)
    assert differs(f, variables, parameters, axis_printed, rng, 1) > 1e-3


# ---------------------------------------------------------------------------------------------
# Eq. 40: kinematic chain log(Ȳ⁻¹ X_1 exp(tξ_1) ⋯ X_n exp(tξ_n)) at Ȳ = X̄_1⋯X̄_n
# ---------------------------------------------------------------------------------------------
def so3_ad_inv(X):
    return X.T  # Ad_{X⁻¹} on SO(3)


def se3_ad_inv(X):
    return pin.SE3(X).inverse().action  # Pinocchio's adjoint, (v, ω) ordering


def so3_bracket(a, b):
    return np.cross(a, b)


def se3_bracket(a, b):
    return pin.Motion(a).cross(pin.Motion(b)).vector


def chain_terms(ad_inv, bracket, n):
    """Eq. 40: Σ Ad_{X_{i+1,n}⁻¹} ξ_i and ½ Σ_{i<j} [Ad_{X_{i+1,n}⁻¹} ξ_i, Ad_{X_{j+1,n}⁻¹} ξ_j]."""

    def terms(v, p, x):
        Xs = [v[f"X{i}"] for i in range(n)]
        a = []
        for i in range(n):
            tail = np.eye(len(Xs[0]))
            for X in Xs[i + 1 :]:
                tail = tail @ X  # X_{i+1,n}
            a.append(ad_inv(tail) @ x[f"X{i}"])
        second = sum(0.5 * bracket(a[i], a[j]) for i in range(n) for j in range(i + 1, n))
        return sum(a), second

    return terms


@pytest.mark.parametrize(
    "group, n",
    [(SO3, 2), (SO3, 3), (SO3, 4), (SE3, 2), (SE3, 3)],
    ids=["SO3-n2", "SO3-n3", "SO3-n4", "SE3-n2", "SE3-n3"],
)
def test_eq40_kinematic_chain(group, n):
    def residual(Yinv, **X):
        return kinematic_chain([X[f"X{i}"] for i in range(n)], Yinv, group)

    f = RiemannianFunction(
        f"t1_chain_{n}_{group.dim}",
        [(f"X{i}", group) for i in range(n)],
        residual,
        [("Yinv", (group.n, group.n))],
    )
    ad_inv, bracket = (so3_ad_inv, so3_bracket) if group is SO3 else (se3_ad_inv, se3_bracket)
    rng = np.random.default_rng(40 + n)
    for _ in range(N_POINTS):
        variables = {f"X{i}": group.random(rng) for i in range(n)}
        Ybar = np.linalg.multi_dot(list(variables.values()))
        parameters = {"Yinv": np.linalg.inv(Ybar)}
        assert np.abs(f.value(variables, parameters)).max() < 1e-12
        assert_terms(f, variables, parameters, chain_terms(ad_inv, bracket, n), rng, atol=1e-10)
