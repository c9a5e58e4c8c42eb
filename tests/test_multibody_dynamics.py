"""Multi-body LGVI (paper §V.A–B): forward simulation vs Pinocchio, joint constraints, exact
derivatives of every multi-body residual, J(x)ᵀλ by hand, warm start by inverse dynamics."""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pinocchio as pin
import pytest

from mbplan.benchmarks import chain_scaling, validate_dynamics
from mbplan.benchmarks.validate_dynamics import (
    constraint_residuals,
    discrete_energy,
    joint_errors,
    joint_trajectory,
    random_state,
    reference,
)
from mbplan.engine import check_derivatives
from mbplan.errors import InputError, RobotModelError
from mbplan.lie import SO3
from mbplan.multibody import MaximalModel, maximal_model, nonstandard_inertia
from mbplan.simulation import integrate_aba, simulate_maximal
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.transcription.multibody import (
    _constraint_function,
    _dynamics_function,
    _joint_forces_function,
    _kinematics_function,
    multibody_layout,
)
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.variables import TrajectoryVariables

ROBOTS = ["iiwa", "double_pendulum"]


@cache
def _mm(name: str) -> MaximalModel:
    return maximal_model(name)


@cache
def _scenario(name: str, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seeded ``q₀``, ``v₀`` and a sane constant torque ``g(q₀) + M(q₀) a``."""
    mm = _mm(name)
    q0, v0, a = random_state(mm, np.random.default_rng(seed))
    tau = pin.rnea(mm.model, mm.model.createData(), q0, np.zeros(mm.nv), a)
    return q0, v0, tau


def _problem(mm: MaximalModel, N: int, dt: float) -> TrajectoryProblem:
    layout = multibody_layout(mm, N, dt, jit=True)
    return TrajectoryProblem(TrajectoryVariables(layout.blocks), layout.terms)


# ----------------------------------------------------------------------- simulation vs Pinocchio


@pytest.mark.parametrize("name", ROBOTS)
def test_simulation_keeps_every_joint_constraint(name: str) -> None:
    mm = _mm(name)
    q0, v0, tau = _scenario(name)
    dt = 0.004
    q1 = reference(mm.model, q0, v0, tau, dt, 1)[1]
    traj = simulate_maximal(mm, q0, q1, tau[mm.idx_v], dt, 20)
    assert constraint_residuals(mm, traj.R, traj.p).max() <= 1e-9
    assert np.abs(np.swapaxes(traj.R, -1, -2) @ traj.R - np.eye(3)).max() <= 1e-12


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_angles_converge_to_pinocchio_with_order_two(name: str) -> None:
    mm = _mm(name)
    q0, v0, tau = _scenario(name)
    h, T = 0.002, 0.1
    q_ref = reference(mm.model, q0, v0, tau, h, round(T / h))
    errors = []
    for dt in (0.004, 0.002):
        stride, N = round(dt / h), round(T / dt)
        traj = simulate_maximal(mm, q_ref[0], q_ref[stride], tau[mm.idx_v], dt, N)
        q = joint_trajectory(mm, traj.R, q_ref[0])
        errors.append(np.abs(joint_errors(mm, q, q_ref[::stride])).max())
    assert errors[0] < 1e-3
    assert 3.0 < errors[0] / errors[1] < 5.5, errors


def test_discrete_energy_matches_pinocchio_energy() -> None:
    """eq. 33's kinetic + potential energy of step 0 ≈ the continuous energy at t = Δt/2."""
    mm = _mm("iiwa")
    q0, v0, _ = _scenario("iiwa")
    dt = 1e-3
    zero = np.zeros(mm.nv)
    q1 = reference(mm.model, q0, v0, zero, dt, 1)[1]
    traj = simulate_maximal(mm, q0, q1, zero, dt, 1)
    E_discrete = discrete_energy(mm, traj.p, traj.F, traj.v, dt)[0]
    q_mid, v_mid = integrate_aba(mm.model, q0, v0, zero, dt / 2, 5)
    data = mm.model.createData()
    E = pin.computeKineticEnergy(mm.model, data, q_mid, v_mid) + pin.computePotentialEnergy(
        mm.model, data, q_mid
    )
    assert abs(E_discrete - E) <= 1e-5 * abs(E)


def test_prismatic_joint_is_rejected_by_the_transcription() -> None:
    mm = maximal_model("panda")  # two prismatic finger joints
    with pytest.raises(RobotModelError, match=r"revolute joints only.*panda_finger_joint1"):
        multibody_layout(mm, 3, 0.01, jit=False)


def test_nan_torque_is_an_input_error() -> None:
    mm = _mm("double_pendulum")
    q = np.zeros(mm.nq)
    with pytest.raises(InputError, match="tau"):
        simulate_maximal(mm, q, q, np.array([0.0, np.nan]), 0.01, 3)


# ------------------------------------------------------------------------- exact derivatives


def _rand_rotation(rng: np.random.Generator) -> np.ndarray:
    return SO3.exp(rng.standard_normal(3))


def _joint_params(
    rng: np.random.Generator, world: bool, dt: float | None = 0.01
) -> dict[str, np.ndarray | float]:
    """Joint parameters; ``dt=None`` for the joint-force functions, which take no time step."""
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    perp = np.linalg.qr(np.column_stack([axis, rng.standard_normal((3, 2))]))[0][:, 1:]
    params = {
        "r_p": rng.standard_normal(3),
        "r_c": rng.standard_normal(3),
        "perp_p": perp,
        "axis_c": axis,
    }
    if dt is not None:
        params["dt"] = dt
    if world:
        params |= {"Rp": _rand_rotation(rng), "pp": rng.standard_normal(3)}
    return params


def _random_variables(f, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        s.name: _rand_rotation(rng) if s.shape == (3, 3) else rng.standard_normal(s.shape)
        for s in f.variables
    }


def _derivative_cases() -> list[tuple[str, object, bool]]:
    cases = [("kinematics", _kinematics_function, None), ("dynamics", _dynamics_function, None)]
    for world in (False, True):
        cases += [("joint_forces", _joint_forces_function, world)]
        cases += [("constraint", _constraint_function, world)]
    return cases


@pytest.mark.parametrize(
    ("kind", "factory", "world"),
    _derivative_cases(),
    ids=[f"{k}{'_world' if w else ''}" for k, _, w in _derivative_cases()],
)
def test_multibody_residual_derivatives_match_finite_differences(kind, factory, world) -> None:
    """Interpreted functions (same expression graph as the JIT ones); Δt = 0.5 so that no part of
    a residual is scaled below the check's absolute floor."""
    rng = np.random.default_rng(7)
    dt = 0.5
    f = factory(False) if world is None else factory(False, world)
    if kind == "kinematics":
        params = {"dt": dt}
    elif kind == "dynamics":
        A = rng.standard_normal((3, 3))
        params = {
            "J": nonstandard_inertia(A @ A.T + np.eye(3)),
            "mass": 2.5,
            "gravity": np.array([0.0, 0.0, -9.81]),
            "dt": dt,
        }
    else:
        params = _joint_params(rng, world, None if kind == "joint_forces" else dt)
    for _ in range(3):
        check = check_derivatives(f, _random_variables(f, rng), params, rng=rng)
        assert check.ok(1e-6), (f.name, check)


def test_joint_forces_equal_hand_derived_jacobian_transpose() -> None:
    """Pivot: parent gets force λ and torque r_p × R_pᵀλ, child -λ and -r_c × R_cᵀλ; axis ``i``
    with multiplier μ_i: torques e_i × R_pᵀR_c a (parent) and a × R_cᵀR_p e_i (child);
    actuation τ: +τ a (child), -τ R_pᵀR_c a (parent). Rows in N·m (torque) and N (force), negated."""
    rng = np.random.default_rng(11)
    params = _joint_params(rng, world=False, dt=None)
    Rp, Rc = _rand_rotation(rng), _rand_rotation(rng)
    pp, pc = rng.standard_normal(3), rng.standard_normal(3)
    lam, tau = rng.standard_normal(5), rng.standard_normal(1)
    f = _joint_forces_function(False, False)
    got = f.value({"Rp": Rp, "pp": pp, "Rc": Rc, "pc": pc, "lam": lam, "tau": tau}, params)[0]

    force, mu, a, e = lam[:3], lam[3:], params["axis_c"], params["perp_p"]
    a_in_parent = Rp.T @ Rc @ a
    torque_p = np.cross(params["r_p"], Rp.T @ force) - tau[0] * a_in_parent
    torque_c = -np.cross(params["r_c"], Rc.T @ force) + tau[0] * a
    for i in range(2):
        torque_p += mu[i] * np.cross(e[:, i], a_in_parent)
        torque_c += mu[i] * np.cross(a, Rc.T @ Rp @ e[:, i])
    expected = np.concatenate([-torque_p, -force, -torque_c, force])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)

    # A joint to the world: the same child rows.
    world = _joint_forces_function(False, True)
    params_w = params | {"Rp": Rp, "pp": pp}
    got_w = world.value({"Rc": Rc, "pc": pc, "lam": lam, "tau": tau}, params_w)[0]
    np.testing.assert_allclose(got_w, expected[6:], rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------------------------- warm start


def _simulated(name: str, dt: float, N: int):
    mm = _mm(name)
    q0, v0, tau = _scenario(name)
    q1 = reference(mm.model, q0, v0, tau, dt, 1)[1]
    traj = simulate_maximal(mm, q0, q1, tau[mm.idx_v], dt, N)
    R = np.concatenate([traj.R, (traj.R[-1] @ traj.F[-1])[None]])  # knots 0 … N+1
    return traj, joint_trajectory(mm, R, q0), tau


@pytest.mark.parametrize("name", ROBOTS)
def test_warm_start_recovers_the_simulated_forces(name: str) -> None:
    mm, dt, N = _mm(name), 0.01, 10
    traj, q, tau = _simulated(name, dt, N)
    point = maximal_warm_start(mm, q, dt, N=N)
    problem = _problem(mm, N, dt)
    _, eq, _ = problem.values(problem.check_point(point))
    assert np.abs(eq).max() <= 1e-8
    scale = max(1.0, np.abs(tau).max())
    tau_ws = point["tau"].reshape(N + 1, mm.nb)
    np.testing.assert_allclose(
        tau_ws[1:], np.broadcast_to(tau[mm.idx_v], (N, mm.nb)), atol=1e-7 * scale
    )
    lam_ws = point["lam"].reshape(N + 1, mm.nb, 5)
    np.testing.assert_allclose(lam_ws[1:], traj.lam[1:], atol=1e-7 * np.abs(traj.lam).max())
    np.testing.assert_allclose(point["F"].reshape(traj.F.shape), traj.F, atol=1e-12)


def test_warm_start_from_pinocchio_is_dynamically_consistent() -> None:
    mm = _mm("iiwa")
    q0, v0, tau = _scenario("iiwa")
    errors = []
    for dt in (0.01, 0.005):
        N = round(0.1 / dt)
        q = reference(mm.model, q0, v0, tau, dt, N + 1)
        point = maximal_warm_start(mm, q, dt, N=N)
        problem = _problem(mm, N, dt)
        assert np.abs(problem.values(point)[1]).max() <= 1e-8
        tau_ws = point["tau"].reshape(N + 1, mm.nb)[1:]
        errors.append(np.abs(tau_ws - tau[mm.idx_v]).max() / np.abs(tau).max())
    assert errors[0] < 1e-3
    assert errors[0] / errors[1] > 3.0, errors  # O(Δt²) or better


def test_warm_start_without_extra_configuration_stops_at_the_last_knot() -> None:
    mm, dt, N = _mm("double_pendulum"), 0.01, 5
    _, q, _ = _simulated("double_pendulum", dt, N)
    point = maximal_warm_start(mm, q[: N + 1], dt)
    np.testing.assert_allclose(point["F"][N], np.eye(3)[None].repeat(mm.nb, 0), atol=1e-15)
    np.testing.assert_array_equal(point["v"][N], 0.0)
    assert np.abs(_problem(mm, N, dt).values(point)[1]).max() <= 1e-8
    with pytest.raises(InputError, match="q_traj"):
        maximal_warm_start(mm, q[:, :1], dt)
    with pytest.raises(InputError, match="q_traj"):
        maximal_warm_start(mm, q, dt, N=2)


# ------------------------------------------------------------------------------ benchmarks


def test_validate_dynamics_writes_its_results(tmp_path) -> None:
    s = validate_dynamics.run(
        "double_pendulum", 0, tmp_path, dts=(0.004, 0.002), T=0.02, long_steps=20
    )
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["dt"] == [0.004, 0.002] and saved["robot"] == s["robot"]
    assert len(saved["max_joint_error_rad"]) == len(saved["energy_drift_rel"]) == 2
    assert max(saved["max_constraint_residual"]) <= 1e-9
    assert set(saved["scenarios"]) == {"passive", "torque"}
    assert saved["long_passive_run"]["steps"] == 20
    assert (tmp_path / "results.md").read_text().startswith("# LGVI")
    assert (tmp_path / "validate_dynamics.png").stat().st_size > 0


def test_validate_dynamics_locks_prismatic_joints() -> None:
    model, locked = validate_dynamics.revolute_model("panda")
    assert locked == ["panda_finger_joint1", "panda_finger_joint2"]
    assert model.nq == 7


def test_chain_scaling_writes_its_results(tmp_path) -> None:
    s = chain_scaling.run(tmp_path, bodies=(1, 3), N=4)
    assert [r["bodies"] for r in s["rows"]] == [1, 3]
    assert all(r["max_residual_at_point"] <= 1e-8 for r in s["rows"])
    assert set(s["ratio_last_over_first"]) == {"bodies", "value", "jacobian", "hessian"}
    assert (tmp_path / "chain_scaling.png").stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["N"] == 4
