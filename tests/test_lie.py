"""Matrix Lie groups: exp/log, adjoints and Jacobians against Pinocchio, SciPy and identities.

Independent references: Pinocchio's ``exp3/log3/Jexp3/Jlog3`` (``Jexp3`` is the right Jacobian)
and ``exp6/log6/SE3.action`` (motion ordering (v, ω)), SciPy's ``expm/logm`` for SO(n)/SL(n),
and finite differences of the definitions for the Jacobians.
"""

from __future__ import annotations

import functools
import math

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg as sla
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mbplan.errors import InputError
from mbplan.lie import SE3, SL, SO, SO3, ProductGroup, R

SETTINGS = settings(max_examples=100, deadline=None)
FEW = settings(max_examples=40, deadline=None)

finite = st.floats(-1.0, 1.0, allow_subnormal=False)
# scipy.linalg.logm (behind SO(n)/SL(n) log) warns from its 1-norm estimator on matrices with
# tiny entries (near identity); the results are still accurate (asserted), so it is noise here.
LOGM_WARNING = "ignore::RuntimeWarning:scipy"


@st.composite
def unit_axes(draw):
    a = draw(arrays(float, 3, elements=finite))
    n = np.linalg.norm(a)
    assume(n > 1e-3)
    return a / n


def tangents(dim: int, bound: float = 1.0):
    return arrays(float, dim, elements=st.floats(-bound, bound, allow_subnormal=False))


def skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def right_jacobian_series(ad: np.ndarray, terms: int = 40) -> np.ndarray:
    """``J_r = Σ_k (-ad_ξ)^k / (k+1)!`` summed directly (converges fast for ‖ad‖ ≲ 10)."""
    out, term = np.zeros_like(ad), np.eye(len(ad))
    for k in range(terms):
        out += term / math.factorial(k + 1)
        term = term @ -ad
    return out


# ---------------------------------------------------------------------------------------------
# SO(3): exp/log round trips over the whole principal range, near π and near 0
# ---------------------------------------------------------------------------------------------
@SETTINGS
@given(axis=unit_axes(), angle=st.floats(0.0, np.pi - 1e-6))
def test_so3_log_inverts_exp_below_pi(axis, angle):
    phi = angle * axis
    Rm = SO3.exp(phi)
    np.testing.assert_allclose(Rm.T @ Rm, np.eye(3), atol=1e-14)
    assert np.linalg.det(Rm) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(SO3.log(Rm), phi, rtol=0, atol=1e-10)


near_pi_offsets = st.one_of(
    st.just(0.0),
    st.sampled_from([1e-16, 1e-15, 1e-14, 1e-13, 1e-12, 1e-10, 1e-8, 1e-7, 1e-6]),
    st.floats(0.0, 1e-6),
)


@SETTINGS
@given(axis=unit_axes(), delta=near_pi_offsets, above=st.booleans())
def test_so3_log_near_pi(axis, delta, above):
    """Angles π ± δ with δ ≤ 1e-6, including exactly π: log is accurate and in [0, π]."""
    theta = np.pi + delta if above else np.pi - delta
    Rm = SO3.exp(theta * axis)
    phi = SO3.log(Rm)
    assert np.linalg.norm(phi) <= np.pi + 1e-12
    np.testing.assert_allclose(SO3.exp(phi), Rm, rtol=0, atol=1e-13)
    # The principal rotation vector: θ a below π, -(2π - θ) a above it.
    expected = theta * axis if not above else (theta - 2 * np.pi) * axis
    if delta > 1e-12:  # the sign of the axis is resolvable from the antisymmetric part
        np.testing.assert_allclose(phi, expected, rtol=0, atol=1e-10)
    else:  # at (numerically) exactly π, ±π a are both logarithms
        err = min(np.abs(phi - expected).max(), np.abs(phi + expected).max())
        assert err < 1e-10


@SETTINGS
@given(
    axis=unit_axes(),
    angle=st.one_of(
        st.just(0.0),
        st.sampled_from([1e-300, 1e-15, 1e-12, 1e-9, 1e-6, 1e-3]),
        st.floats(0.0, 1e-3),
        st.floats(1e-13, 1e-11),
    ),
)
def test_so3_log_inverts_exp_near_zero(axis, angle):
    """Tiny angles (down to ~1e-12 and below): relative accuracy, no cancellation."""
    phi = angle * axis
    out = SO3.log(SO3.exp(phi))
    assert np.linalg.norm(out - phi) <= 1e-12 * angle + 1e-300
    # Jacobians are smooth at 0: J_r = I - φ^/2 + O(θ²), J_r⁻¹ = I + φ^/2 + O(θ²).
    np.testing.assert_allclose(SO3.jac_right(phi), np.eye(3) - skew(phi) / 2, atol=angle**2)
    np.testing.assert_allclose(SO3.jac_right_inv(phi), np.eye(3) + skew(phi) / 2, atol=angle**2)


def test_so3_log_at_exact_special_rotations():
    assert np.array_equal(SO3.log(np.eye(3)), np.zeros(3))
    for i in range(3):  # rotations by exactly π about the coordinate axes
        Rm = -np.eye(3)
        Rm[i, i] = 1.0
        phi = SO3.log(Rm)
        expected = np.zeros(3)
        expected[i] = np.pi
        assert min(np.abs(phi - expected).max(), np.abs(phi + expected).max()) < 1e-15


# ---------------------------------------------------------------------------------------------
# SO(3) and SE(3) against Pinocchio
# ---------------------------------------------------------------------------------------------
so3_angles = st.one_of(
    st.floats(0.0, np.pi),
    st.floats(0.0, 1e-5),
    st.builds(lambda d: np.pi - d, st.floats(0.0, 1e-6)),
)


@SETTINGS
@given(axis=unit_axes(), angle=so3_angles)
def test_so3_matches_pinocchio(axis, angle):
    phi = angle * axis
    Rm = SO3.exp(phi)
    np.testing.assert_allclose(Rm, pin.exp3(phi), rtol=0, atol=1e-14)
    log_pin = pin.log3(Rm)
    log_ours = SO3.log(Rm)
    if np.pi - angle > 1e-12:
        np.testing.assert_allclose(log_ours, log_pin, rtol=0, atol=1e-10)
    else:  # sign of the axis at π is a convention
        assert min(np.abs(log_ours - log_pin).max(), np.abs(log_ours + log_pin).max()) < 1e-10
    # Pinocchio's Jexp3 is the right Jacobian; Jlog3(R) = J_r⁻¹(log3(R)).
    np.testing.assert_allclose(SO3.jac_right(phi), pin.Jexp3(phi), rtol=0, atol=1e-10)
    np.testing.assert_allclose(SO3.jac_right(phi), right_jacobian_series(skew(phi)), atol=1e-13)
    # Pinocchio's closed-form Jlog3 cancels in floating point above its Taylor switch (1.0e-9 off
    # at angle 2.9e-4, found by hypothesis): compare within eps / angle²; the inverse check below
    # is the tight one at every angle.
    cancellation = 2e-16 / angle**2 if angle > 1e-6 else 0.0  # below: Pinocchio's Taylor branch
    atol = 1e-9 + cancellation
    np.testing.assert_allclose(SO3.jac_right_inv(log_pin), pin.Jlog3(Rm), rtol=0, atol=atol)
    if np.pi - angle > 1e-6:  # J_r is singular at π
        np.testing.assert_allclose(
            SO3.jac_right_inv(phi) @ SO3.jac_right(phi), np.eye(3), atol=1e-12
        )
    np.testing.assert_allclose(SO3.Ad(Rm), Rm)


@SETTINGS
@given(v=tangents(3, 5.0), axis=unit_axes(), angle=so3_angles)
@example(v=np.ones(3), axis=np.array([0.0, 0.0, 1.0]), angle=4.25e-4)
def test_se3_matches_pinocchio(v, axis, angle):
    xi = np.concatenate([v, angle * axis])  # Pinocchio motion ordering (v, ω)
    T = SE3.exp(xi)
    M = pin.exp6(xi)
    np.testing.assert_allclose(T, M.homogeneous, rtol=0, atol=1e-12)
    np.testing.assert_allclose(SE3.Ad(T), M.action, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(SE3.Ad(T)), M.inverse().action, atol=1e-10)
    # Pinocchio's Jexp6 cancels in floating point below angle ~1e-2 until it switches to its Taylor
    # branch (error 8.6e-6 at angle 4.25e-4 with |v| ~ 5, found by hypothesis): compare within that
    # cancellation bound, eps·|v| / angle³; the series below is the tight check at every angle.
    cancellation = 1e-15 * (1.0 + np.linalg.norm(v)) / max(angle, 1e-300) ** 3
    np.testing.assert_allclose(
        SE3.jac_right(xi), pin.Jexp6(xi), rtol=0, atol=max(1e-10, min(cancellation, 1e-3))
    )
    ad = np.column_stack([pin.Motion(xi).cross(pin.Motion(e)).vector for e in np.eye(6)])
    np.testing.assert_allclose(SE3.jac_right(xi), right_jacobian_series(ad), rtol=0, atol=1e-13)
    if np.pi - angle > 1e-12:
        np.testing.assert_allclose(SE3.log(T), pin.log6(M).vector, rtol=0, atol=1e-8)
        np.testing.assert_allclose(SE3.log(T), xi, rtol=0, atol=1e-8)
    np.testing.assert_allclose(SE3.exp(SE3.log(T)), T, rtol=0, atol=1e-10)


@SETTINGS
@given(x=tangents(6, 2.0), y=tangents(6, 2.0))
def test_se3_ad_is_pinocchio_motion_cross(x, y):
    expected = pin.Motion(x).cross(pin.Motion(y)).vector
    np.testing.assert_allclose(SE3.ad(x) @ y, expected, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Identities for every group (including R^n and a product)
# ---------------------------------------------------------------------------------------------
PRODUCT = ProductGroup([SO3, R(3), SE3])
GROUPS = [SO3, SE3, SO(2), SO(4), SO(5), SL(2), SL(3), SL(4), R(3), PRODUCT]
ids = [repr(G) for G in GROUPS]


def flat(X) -> np.ndarray:
    """Elements as one flat array (product elements are tuples)."""
    if isinstance(X, tuple):
        return np.concatenate([np.ravel(x) for x in X])
    return np.ravel(X)


def scale_for(G) -> float:
    """Per-entry tangent bound keeping exp inside the domain of the principal log.

    ``‖ξ^‖₂ ≤ √2 ‖ξ‖`` for the SO(n)/SL(n) bases, so ``‖ξ‖ ≤ 2/√2`` keeps every rotation angle
    (imaginary part of an eigenvalue of ξ^) at most 2 < π.
    """
    if G in (SO3, SE3, PRODUCT) or repr(G).startswith("R^"):
        return 1.0
    return (1.0 if repr(G).startswith("SO") else 0.7) / np.sqrt(G.dim)


@pytest.mark.parametrize("G", GROUPS, ids=ids)
@FEW
@given(data=st.data())
def test_adjoint_identities(G, data):
    s = scale_for(G)
    x, y, xi, eta = (data.draw(tangents(G.dim, s)) for _ in range(4))
    X, Y = G.exp(x), G.exp(y)
    # X exp(ξ) X⁻¹ = exp(Ad_X ξ)
    lhs = G.compose(G.compose(X, G.exp(xi)), G.inverse(X))
    np.testing.assert_allclose(flat(lhs), flat(G.exp(G.Ad(X) @ xi)), atol=1e-10)
    # Ad_{XY} = Ad_X Ad_Y and Ad_{X⁻¹} = Ad_X⁻¹
    np.testing.assert_allclose(G.Ad(G.compose(X, Y)), G.Ad(X) @ G.Ad(Y), atol=1e-10)
    np.testing.assert_allclose(G.Ad(G.inverse(X)) @ G.Ad(X), np.eye(G.dim), atol=1e-10)
    # ad_ξ η = -ad_η ξ, Jacobi identity
    np.testing.assert_allclose(G.ad(xi) @ eta, -G.ad(eta) @ xi, atol=1e-12)
    jacobi = G.ad(x) @ G.ad(xi) @ eta + G.ad(xi) @ G.ad(eta) @ x + G.ad(eta) @ G.ad(x) @ xi
    np.testing.assert_allclose(jacobi, 0.0, atol=1e-12)
    # Ad_{exp ξ} = expm(ad_ξ)
    np.testing.assert_allclose(G.Ad(G.exp(xi)), sla.expm(G.ad(xi)), atol=1e-10)
    # J_l(ξ) = Ad_{exp ξ} J_r(ξ), and J_l(ξ) = J_r(-ξ)
    np.testing.assert_allclose(G.jac_left(xi), G.Ad(G.exp(xi)) @ G.jac_right(xi), atol=1e-10)
    np.testing.assert_allclose(G.jac_left(xi), G.jac_right(-xi), atol=1e-12)
    # log inverts exp inside the principal domain
    np.testing.assert_allclose(G.log(G.exp(xi)), xi, atol=1e-10)


MATRIX_GROUPS = [G for G in GROUPS if G not in (PRODUCT,) and repr(G) != "R^3"]


@pytest.mark.parametrize("G", MATRIX_GROUPS, ids=[repr(G) for G in MATRIX_GROUPS])
@FEW
@given(data=st.data())
def test_adjoint_matches_definitions(G, data):
    """Eq. 14 ``Ad_X ξ = (X ξ^ X⁻¹)^∨`` and eq. 15 ``ad_ξ η = [ξ^, η^]^∨``; hat/vee round trip."""
    s = scale_for(G)
    x, xi, eta = (data.draw(tangents(G.dim, s)) for _ in range(3))
    X = G.exp(x)
    A, B = G.hat(xi), G.hat(eta)
    np.testing.assert_allclose(G.vee(A), xi, atol=1e-14)
    np.testing.assert_allclose(G.Ad(X) @ xi, G.vee(X @ A @ np.linalg.inv(X)), atol=1e-10)
    np.testing.assert_allclose(G.ad(xi) @ eta, G.vee(A @ B - B @ A), atol=1e-12)
    np.testing.assert_allclose(G.exp(xi), sla.expm(A), atol=1e-12)


@pytest.mark.parametrize("G", GROUPS, ids=ids)
@pytest.mark.filterwarnings(LOGM_WARNING)
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_jacobians_match_their_definitions(G, data):
    """``log(exp(ξ)⁻¹ exp(ξ+δ)) ≈ J_r(ξ) δ`` and ``log(exp(ξ+δ) exp(ξ)⁻¹) ≈ J_l(ξ) δ``."""
    xi = data.draw(tangents(G.dim, scale_for(G)))
    E = G.exp(xi)
    Einv = G.inverse(E)
    h = 1e-5
    Jr_fd = np.zeros((G.dim, G.dim))
    Jl_fd = np.zeros((G.dim, G.dim))
    for j in range(G.dim):
        d = h * np.eye(G.dim)[j]
        Jr_fd[:, j] = (G.local(E, G.exp(xi + d)) - G.local(E, G.exp(xi - d))) / (2 * h)
        right = G.log(G.compose(G.exp(xi + d), Einv)) - G.log(G.compose(G.exp(xi - d), Einv))
        Jl_fd[:, j] = right / (2 * h)
    np.testing.assert_allclose(G.jac_right(xi), Jr_fd, atol=1e-7)
    np.testing.assert_allclose(G.jac_left(xi), Jl_fd, atol=1e-7)
    if hasattr(G, "jac_right_inv"):
        np.testing.assert_allclose(G.jac_right_inv(xi) @ G.jac_right(xi), np.eye(G.dim), atol=1e-10)
        np.testing.assert_allclose(G.jac_left_inv(xi) @ G.jac_left(xi), np.eye(G.dim), atol=1e-10)


@SETTINGS
@given(axis=unit_axes(), angle=st.floats(0.0, 2 * np.pi - 0.1))
def test_so3_jacobian_inverses_over_whole_range(axis, angle):
    """Closed-form J_r⁻¹, J_l⁻¹ are the inverses of J_r, J_l for angles up to ~2π."""
    phi = angle * axis
    for J, Jinv in [(SO3.jac_right, SO3.jac_right_inv), (SO3.jac_left, SO3.jac_left_inv)]:
        np.testing.assert_allclose(Jinv(phi) @ J(phi), np.eye(3), atol=1e-9)


# ---------------------------------------------------------------------------------------------
# SO(n) and SL(n) against SciPy
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [2, 3, 4, 5])
@pytest.mark.filterwarnings(LOGM_WARNING)
@FEW
@given(data=st.data())
def test_son_sln_match_scipy(n, data):
    for G, bound, algebra_ok in [
        (SO(n), 2.0 / n, lambda A: np.allclose(A, -A.T, atol=1e-14)),
        (SL(n), 0.6 / n, lambda A: abs(np.trace(A)) < 1e-13),
    ]:
        xi = data.draw(tangents(G.dim, bound))
        A = G.hat(xi)
        assert algebra_ok(A)
        X = G.exp(xi)
        np.testing.assert_allclose(X, sla.expm(A), rtol=0, atol=1e-12)
        L = sla.logm(X)
        L = np.real_if_close(L)
        np.testing.assert_allclose(G.hat(G.log(X)), L, rtol=0, atol=1e-10)
        np.testing.assert_allclose(G.log(X), xi, rtol=0, atol=1e-10)


@pytest.mark.parametrize("n", [2, 4, 5])
def test_son_log_close_to_pi(n):
    G = SO(n)
    xi = np.zeros(G.dim)
    xi[0] = np.pi - 1e-4  # rotation in the (e_1, e_2) plane
    np.testing.assert_allclose(G.log(G.exp(xi)), xi, atol=1e-10)


# SO(n) log at angle π (real Schur form; scipy's logm goes complex there).
@pytest.mark.parametrize(
    "X",
    [-np.eye(2), np.diag([-1.0, -1.0, 1.0, 1.0]), SO(2).exp([np.pi - 1e-9])],
    ids=["SO2 at pi", "SO4 at pi", "SO2 pi-1e-9"],
)
def test_son_log_at_pi(X):
    G = SO(len(X))
    phi = G.log(X)
    np.testing.assert_allclose(G.exp(phi), X, atol=1e-12)


def test_group_dimensions():
    assert [SO(n).dim for n in range(2, 6)] == [1, 3, 6, 10]
    assert [SL(n).dim for n in range(2, 6)] == [3, 8, 15, 24]
    assert SE3.dim == 6 and PRODUCT.dim == 12


@pytest.mark.parametrize(
    "X",
    [
        np.diag([-1.0, -1.0, 1.0]),
        np.diag([-2.0, -0.5]),
        -np.eye(2),
        np.diag([-1.0, -1.0, 2.0, 0.5]),
        np.array([[-1.0, 5.0], [0.0, -1.0]]),  # defective, eigenvalue -1
    ],
    ids=["diag(-1,-1,1)", "diag(-2,-0.5)", "-I2", "diag(-1,-1,2,.5)", "jordan(-1)"],
)
def test_sln_log_outside_domain_raises(X):
    G = SL(len(X))
    rng = np.random.default_rng(len(X))
    P = np.eye(len(X)) + 0.3 * rng.standard_normal(X.shape)
    for Y in (X, P @ X @ np.linalg.inv(P)):  # also a non-diagonal conjugate
        with pytest.raises(InputError, match="negative real axis"):
            G.log(Y)


def test_sln_log_near_but_inside_domain():
    """Complex eigenvalues close to (not on) the negative axis still have a real log."""
    G = SL(2)
    theta = np.pi - 1e-3
    X = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    np.testing.assert_allclose(G.exp(G.log(X)), X, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# Symbolic (CasADi SX) variants agree with the numeric ones
# ---------------------------------------------------------------------------------------------
TANGENT_OPS = ("exp", "ad", "hat", "jac_right", "jac_left", "jac_right_inv", "jac_left_inv")
ELEMENT_OPS = ("Ad", "inverse", "log")


@functools.cache
def symbolic(G, op: str) -> cs.Function:
    if op in TANGENT_OPS:
        x = cs.SX.sym("x", G.dim)
    else:
        x = cs.SX.sym("X", G.n, G.n)
    return cs.Function(op, [x], [getattr(G, op)(x)])


def sym_eval(G, op, arg) -> np.ndarray:
    return np.asarray(symbolic(G, op)(arg).full()).squeeze()


@pytest.mark.parametrize("G", [SO3, SE3], ids=["SO3", "SE3"])
@SETTINGS
@given(data=st.data())
def test_symbolic_matches_numeric_so3_se3(G, data):
    axis = data.draw(unit_axes())
    angle = data.draw(
        st.one_of(
            st.floats(0.0, np.pi),
            st.floats(0.0, 1e-5),
            st.builds(lambda d: np.pi - d, st.floats(1e-11, 1e-6)),
        )
    )
    xi = angle * axis if G is SO3 else np.concatenate([data.draw(tangents(3, 3.0)), angle * axis])
    for op in TANGENT_OPS:
        want = getattr(G, op)(xi)
        np.testing.assert_allclose(sym_eval(G, op, xi), want, rtol=1e-12, atol=1e-12, err_msg=op)
    X = G.exp(xi)
    for op in ELEMENT_OPS:
        want = getattr(G, op)(X)
        np.testing.assert_allclose(sym_eval(G, op, X), want, rtol=1e-10, atol=1e-10, err_msg=op)
    # log(exp(ξ)) = ξ except at angle π, where ±axis are both logarithms: compare through exp.
    np.testing.assert_allclose(G.exp(sym_eval(G, "log", X)), X, atol=1e-8)


@pytest.mark.parametrize("G", [SO3, SE3], ids=["SO3", "SE3"])
def test_symbolic_log_at_exact_pi_and_identity(G):
    specials = [np.eye(G.n)]
    for i in range(3):
        Rm = -np.eye(3)
        Rm[i, i] = 1.0
        X = np.eye(G.n)
        X[:3, :3] = Rm
        specials.append(X)
    for X in specials:
        out = sym_eval(G, "log", X)
        assert np.all(np.isfinite(out))
        np.testing.assert_allclose(G.exp(out), X, atol=1e-14)
        np.testing.assert_allclose(np.abs(out), np.abs(G.log(X)), atol=1e-14)


@pytest.mark.parametrize("G", [SO(2), SO(4), SL(3)], ids=["SO2", "SO4", "SL3"])
@FEW
@given(data=st.data())
def test_symbolic_matches_numeric_generic(G, data):
    xi = data.draw(tangents(G.dim, 0.8))
    for op in TANGENT_OPS:
        want = getattr(G, op)(xi)
        got = sym_eval(G, op, xi).reshape(np.shape(want))
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-11, err_msg=op)
    X = G.exp(xi)
    for op in ("Ad", "inverse"):
        got = sym_eval(G, op, X).reshape(G.Ad(X).shape if op == "Ad" else X.shape)
        np.testing.assert_allclose(got, getattr(G, op)(X), rtol=1e-11, atol=1e-11)


def test_symbolic_log_of_generic_group_is_refused():
    with pytest.raises(InputError, match="no symbolic form"):
        SO(4).log(cs.SX.sym("X", 4, 4))


# ---------------------------------------------------------------------------------------------
# Batched (leading dimensions) numeric calls
# ---------------------------------------------------------------------------------------------
BATCH_GROUPS = [SO3, SE3, SO(2), SO(4), SL(3)]


@pytest.mark.parametrize("G", BATCH_GROUPS, ids=[repr(G) for G in BATCH_GROUPS])
def test_batched_calls_equal_per_element_calls(G):
    rng = np.random.default_rng(7)
    xis = scale_for(G) * rng.standard_normal((2, 3, G.dim))
    if G is SO3:  # mix in the special branches of log: near π, exactly π, near 0, exactly 0
        a = np.array([0.0, 0.6, 0.8])
        xis[0, 0] = (np.pi - 1e-9) * a
        xis[0, 1] = np.pi * a
        xis[0, 2] = 1e-12 * a
        xis[1, 0] = 0.0
    Xs = G.exp(xis)
    Ys = G.exp(np.flip(xis, axis=1).copy())
    assert Xs.shape == (2, 3, G.n, G.n)
    batched = {op: getattr(G, op)(xis) for op in TANGENT_OPS}
    batched |= {op: getattr(G, op)(Xs) for op in ELEMENT_OPS}
    batched["compose"] = G.compose(Xs, Ys)
    batched["vee"] = G.vee(batched["hat"])
    for i in range(2):
        for j in range(3):
            for op in TANGENT_OPS:
                np.testing.assert_allclose(
                    batched[op][i, j], getattr(G, op)(xis[i, j]), rtol=0, atol=1e-14, err_msg=op
                )
            for op in ELEMENT_OPS:
                np.testing.assert_allclose(
                    batched[op][i, j], getattr(G, op)(Xs[i, j]), rtol=0, atol=1e-14, err_msg=op
                )
            np.testing.assert_allclose(batched["compose"][i, j], Xs[i, j] @ Ys[i, j], atol=1e-15)
            np.testing.assert_allclose(batched["vee"][i, j], xis[i, j], atol=1e-15)


def test_empty_batch():
    assert SO3.exp(np.zeros((0, 3))).shape == (0, 3, 3)
    assert SO(4).exp(np.zeros((0, 6))).shape == (0, 4, 4)


# ---------------------------------------------------------------------------------------------
# Bad input raises InputError naming the problem
# ---------------------------------------------------------------------------------------------
def _with(X, i, j, value):
    X = np.array(X, dtype=float)
    X[i, j] = value
    return X


BAD_INPUTS = [
    ("so3 exp short vector", lambda: SO3.exp(np.zeros(2)), r"SO\(3\) tangent.*shape"),
    ("so3 exp NaN", lambda: SO3.exp([0.1, np.nan, 0.2]), "NaN"),
    ("so3 exp inf", lambda: SO3.jac_right([0.1, np.inf, 0.2]), "NaN or inf"),
    ("so3 exp string", lambda: SO3.exp("abc"), "cannot convert"),
    ("so3 log 4x4", lambda: SO3.log(np.eye(4)), r"SO\(3\) element.*shape"),
    ("so3 log 3-vector", lambda: SO3.log(np.zeros(3)), "shape"),
    ("so3 log non-orthogonal", lambda: SO3.log(np.eye(3) + 1e-3), "not orthogonal"),
    ("so3 log scaled", lambda: SO3.Ad(1.1 * np.eye(3)), "not orthogonal"),
    ("so3 log det -1", lambda: SO3.log(np.diag([1.0, 1.0, -1.0])), "determinant"),
    ("so3 log NaN", lambda: SO3.log(_with(np.eye(3), 0, 1, np.nan)), "NaN"),
    (
        "so3 batch with one reflection",
        lambda: SO3.log(np.stack([np.eye(3), np.diag([1.0, -1.0, -1.0]), -np.eye(3)])),
        "determinant",
    ),
    ("so3 compose bad", lambda: SO3.compose(np.eye(3), np.ones((3, 3))), "not orthogonal"),
    ("so3 vee wrong shape", lambda: SO3.vee(np.zeros((4, 4))), "shape"),
    ("se3 bad last row", lambda: SE3.log(_with(np.eye(4), 3, 0, 0.5)), "last row"),
    ("se3 bad corner", lambda: SE3.inverse(_with(np.eye(4), 3, 3, 2.0)), "last row"),
    (
        "se3 reflected rotation",
        lambda: SE3.Ad(np.diag([1.0, 1.0, -1.0, 1.0])),
        "rotation block.*determinant",
    ),
    ("se3 exp 3-vector", lambda: SE3.exp(np.zeros(3)), r"SE\(3\) tangent.*shape"),
    ("se3 3x3", lambda: SE3.log(np.eye(3)), "shape"),
    ("sl3 det 8", lambda: SL(3).log(2 * np.eye(3)), "determinant is not 1"),
    ("sl2 det 0", lambda: SL(2).Ad(np.zeros((2, 2))), "determinant is not 1"),
    ("so4 reflection", lambda: SO(4).log(np.diag([1.0, 1.0, 1.0, -1.0])), "determinant"),
    ("so4 NaN tangent", lambda: SO(4).exp(np.full(6, np.nan)), "NaN"),
    ("so4 wrong dim", lambda: SO(4).exp(np.zeros(5)), "shape"),
    ("son n=1", lambda: SO(1), "n >= 2"),
    ("sln n=1", lambda: SL(1), "n >= 2"),
    ("rn element", lambda: R(3).compose(np.zeros(3), np.zeros(2)), "shape"),
    ("rn NaN", lambda: R(3).exp([0.0, np.nan, 0.0]), "NaN"),
    ("product tangent", lambda: PRODUCT.exp(np.zeros(11)), "12 entries"),
    ("product element", lambda: PRODUCT.log((np.eye(3), np.zeros(3))), "3 components"),
    ("product empty", lambda: ProductGroup([]), "at least one"),
    ("symbolic shape", lambda: SO3.exp(cs.SX.sym("x", 4)), "3x1"),
    ("symbolic element", lambda: SE3.Ad(cs.SX.sym("X", 3, 3)), "4x4"),
]


@pytest.mark.parametrize("call, match", [c[1:] for c in BAD_INPUTS], ids=[c[0] for c in BAD_INPUTS])
def test_bad_input_raises_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_input_error_is_a_value_error():
    with pytest.raises(ValueError):
        SO3.log(np.diag([1.0, 1.0, -1.0]))


def test_membership_tolerance_accepts_rounding_noise():
    rng = np.random.default_rng(3)
    Rm = SO3.exp(rng.standard_normal(3)) + 1e-9 * rng.standard_normal((3, 3))
    assert np.all(np.isfinite(SO3.log(Rm)))


def test_rn_is_one_group_per_dimension_and_refuses_a_non_integer_dimension():
    from mbplan.errors import InputError
    from mbplan.lie import R

    assert R(3) is R(np.int64(3)) and R(3).n == 3 and type(R(np.int64(3)).n) is int
    with pytest.raises(InputError, match=r"integer n, got 3\.0"):
        R(3.0)
    with pytest.raises(InputError, match="n >= 1"):
        R(0)
