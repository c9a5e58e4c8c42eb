"""Multi-body LGVI (paper §V.A–B): forward simulation vs Pinocchio, joint constraints (revolute,
continuous, prismatic), damping, exact derivatives of every multi-body residual, J(x)ᵀλ by hand,
warm start by inverse dynamics."""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pinocchio as pin
import pytest

from mbplan.benchmarks import chain_scaling, validate_dynamics
from mbplan.benchmarks.dynamics_scenario import joint_errors, smooth_scenario
from mbplan.benchmarks.validate_dynamics import damping_variants, validate_case
from mbplan.engine import check_derivatives
from mbplan.errors import InputError, MbplanError
from mbplan.lie import SO3
from mbplan.multibody import (
    MaximalModel,
    joint_constraint_residuals,
    joint_positions,
    maximal_model,
    nonstandard_inertia,
)
from mbplan.simulation import discrete_energy, integrate_aba, simulate_maximal
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.transcription.multibody import (
    _constraint_function,
    _damping_function,
    _dynamics_function,
    _joint_forces_function,
    _kinematics_function,
    multibody_layout,
)
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import TrajectoryVariables

# revolute (damped), revolute (damping zeroed), continuous, prismatic + revolute
ROBOTS = ["iiwa", "double_pendulum", "double_pendulum_continuous", "panda"]


@cache
def _mm(name: str, damped: bool = True) -> MaximalModel:
    model = damping_variants(name)["damped" if damped else "undamped"][0]
    if damped and name == "double_pendulum":
        model.damping[:] = 0.0  # one robot without damping terms at all
    return maximal_model(model)


@cache
def _reference(name: str, dt: float, N: int, seed: int = 3):
    """The smooth scenario of ``name``: ``q`` at ``t = kΔt`` (k = 0..N+1) and the knot torques."""
    mm = _mm(name)
    sc = smooth_scenario(mm, seed)
    q, _ = sc.reference(dt, N + 1, 16)
    tau = np.array([sc.torque(k * dt)[mm.idx_v] for k in range(N + 1)])
    return q, tau


def _problem(mm: MaximalModel, N: int, dt: float) -> TrajectoryProblem:
    layout = multibody_layout(mm, N, dt, jit=True)
    return TrajectoryProblem(TrajectoryVariables(layout.blocks), layout.terms)


# ----------------------------------------------------------------------- simulation vs Pinocchio


@pytest.mark.parametrize("name", ROBOTS)
def test_simulation_keeps_every_joint_constraint(name: str) -> None:
    mm, dt, N = _mm(name), 0.004, 20
    q, tau = _reference(name, dt, N)
    traj = simulate_maximal(mm, q[0], q[1], tau, dt, N)
    assert joint_constraint_residuals(mm, traj.R, traj.p).max() <= 1e-10
    assert np.abs(np.swapaxes(traj.R, -1, -2) @ traj.R - np.eye(3)).max() <= 1e-12
    q_lgvi = joint_positions(mm, traj.R, traj.p, q_ref=q[0])
    assert np.abs(joint_errors(mm, q_lgvi, q[: N + 1])).max() < 1e-3


@pytest.mark.parametrize("name", ["iiwa", "panda"])
def test_damped_lgvi_converges_to_damped_pinocchio_with_order_two(name: str) -> None:
    """The CI-sized `mbplan validate-dynamics`: smooth scenario, 3 step sizes, fitted order."""
    model = damping_variants(name)["damped"][0]
    case = validate_case(model, 0, (0.004, 0.002, 0.001), 0.04)
    assert 1.8 <= case["observed_order"] <= 2.2, case
    assert case["euler_observed_order"] < 1.3, case  # a first-order method is told apart
    assert case["runs"][-1]["max_joint_error"] <= 1e-4
    assert max(r["max_constraint_residual"] for r in case["runs"]) <= 1e-10


def test_damping_changes_the_motion_by_far_more_than_the_error() -> None:
    """The undamped LGVI misses the damped reference: damping is really in the integrator."""
    name, dt, N = "iiwa", 0.002, 40
    q, tau = _reference(name, dt, N)
    errors = {}
    for damped in (True, False):
        mm = _mm(name, damped)
        traj = simulate_maximal(mm, q[0], q[1], tau, dt, N)
        q_lgvi = joint_positions(mm, traj.R, traj.p, q_ref=q[0])
        errors[damped] = np.abs(joint_errors(mm, q_lgvi, q[: N + 1])).max()
    assert errors[False] > 30 * errors[True], errors


def test_discrete_energy_matches_pinocchio_energy() -> None:
    """eq. 33's kinetic + potential energy of step 0 ≈ the continuous energy at t = Δt/2."""
    mm = _mm("iiwa", damped=False)
    q0 = smooth_scenario(mm, 3).q0
    v0 = np.random.default_rng(3).standard_normal(mm.nv)
    dt = 1e-3
    zero = np.zeros(mm.nv)
    q1 = integrate_aba(mm.model, q0, v0, zero, dt, 10)[0]
    traj = simulate_maximal(mm, q0, q1, zero, dt, 1)
    E_discrete = discrete_energy(mm, traj.p, traj.F, traj.v, dt)[0]
    q_mid, v_mid = integrate_aba(mm.model, q0, v0, zero, dt / 2, 5)
    data = mm.model.createData()
    E = pin.computeKineticEnergy(mm.model, data, q_mid, v_mid) + pin.computePotentialEnergy(
        mm.model, data, q_mid
    )
    assert abs(E_discrete - E) <= 1e-5 * abs(E)


def test_prismatic_and_damped_joints_have_their_own_terms() -> None:
    names = {t.name for t in multibody_layout(_mm("panda"), 3, 0.01, jit=False).terms}
    assert {"prismatic_joint_forces", "prismatic_joint_constraints"} <= names
    assert {"joint_damping", "joint_damping_world", "prismatic_joint_damping"} <= names
    plain = {t.name for t in multibody_layout(_mm("double_pendulum"), 3, 0.01, jit=False).terms}
    assert not any("damping" in n or "prismatic" in n for n in plain)


def test_nan_torque_is_an_input_error() -> None:
    mm = _mm("double_pendulum")
    q = np.zeros(mm.nq)
    with pytest.raises(InputError, match="tau"):
        simulate_maximal(mm, q, q, np.array([0.0, np.nan]), 0.01, 3)


# ------------------------------------------------------------------------- exact derivatives


def _rand_rotation(rng: np.random.Generator) -> np.ndarray:
    return SO3.exp(rng.standard_normal(3))


def _unit(rng: np.random.Generator) -> np.ndarray:
    a = rng.standard_normal(3)
    return a / np.linalg.norm(a)


def _joint_params(rng: np.random.Generator, f) -> dict[str, np.ndarray | float]:
    """Random parameters of a joint function ``f`` (unit axes, orthonormal ``perp_p``)."""
    params: dict[str, np.ndarray | float] = {}
    for s in f.parameters:
        if s.name == "perp_p":
            axis = _unit(rng)
            basis = np.linalg.qr(np.column_stack([axis, rng.standard_normal((3, 2))]))[0]
            params[s.name] = basis[:, 1:]
        elif s.name.startswith("axis"):
            params[s.name] = _unit(rng)
        elif s.shape == (3, 3):
            params[s.name] = _rand_rotation(rng)
        elif s.name in ("dt", "damping"):
            params[s.name] = 0.5
        else:
            params[s.name] = rng.standard_normal(s.shape)
    return params


def _random_variables(f, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        s.name: _rand_rotation(rng) if s.shape == (3, 3) else rng.standard_normal(s.shape)
        for s in f.variables
    }


_JOINT_FACTORIES = {
    "joint_forces": _joint_forces_function,
    "constraint": _constraint_function,
    "damping": _damping_function,
}


def _derivative_cases() -> list[tuple[str, str | None, bool | None]]:
    cases: list[tuple[str, str | None, bool | None]] = [
        ("kinematics", None, None),
        ("dynamics", None, None),
    ]
    for kind in _JOINT_FACTORIES:
        for joint in ("revolute", "prismatic"):
            cases += [(kind, joint, world) for world in (False, True)]
    return cases


@pytest.mark.parametrize(
    ("kind", "joint", "world"),
    _derivative_cases(),
    ids=[f"{k}{'_' + j if j else ''}{'_world' if w else ''}" for k, j, w in _derivative_cases()],
)
def test_multibody_residual_derivatives_match_finite_differences(kind, joint, world) -> None:
    """Interpreted functions (same expression graph as the JIT ones); Δt = 0.5 so that no part of
    a residual is scaled below the check's absolute floor."""
    rng = np.random.default_rng(7)
    dt = 0.5
    if kind == "kinematics":
        f, params = _kinematics_function(False), {"dt": dt}
    elif kind == "dynamics":
        A = rng.standard_normal((3, 3))
        f = _dynamics_function(False)
        params = {
            "J": nonstandard_inertia(A @ A.T + np.eye(3)),
            "mass": 2.5,
            "gravity": np.array([0.0, 0.0, -9.81]),
            "dt": dt,
        }
    else:
        f = _JOINT_FACTORIES[kind](False, world, joint)
        params = _joint_params(rng, f)
    for _ in range(3):
        check = check_derivatives(f, _random_variables(f, rng), params, rng=rng)
        assert check.ok(1e-6), (f.name, check)


def test_joint_forces_equal_hand_derived_jacobian_transpose() -> None:
    """Pivot: parent gets force λ and torque r_p × R_pᵀλ, child -λ and -r_c × R_cᵀλ; axis ``i``
    with multiplier μ_i: torques e_i × R_pᵀR_c a (parent) and a × R_cᵀR_p e_i (child);
    actuation τ: +τ a (child), -τ R_pᵀR_c a (parent). Rows in N·m (torque) and N (force), negated."""
    rng = np.random.default_rng(11)
    f = _joint_forces_function(False, False)
    params = _joint_params(rng, f)
    Rp, Rc = _rand_rotation(rng), _rand_rotation(rng)
    pp, pc = rng.standard_normal(3), rng.standard_normal(3)
    lam, tau = rng.standard_normal(5), rng.standard_normal(1)
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


def test_prismatic_forces_equal_hand_derived_jacobian_transpose() -> None:
    """Slide force f along ``a_w = R_p a_p`` between the pivots (gap ``Δ``): child force ``f a_w``
    and torque ``f r_c × R_cᵀa_w``, parent force ``-f a_w`` and torque ``f (a_p × R_pᵀΔ - r_p ×
    a_p)``; rotation multipliers μ: torques ``∓ ½ R_rel0 (tr(M)I - M)ᵀ…`` checked through the
    equal-and-opposite torque balance; slide multipliers ν: force ``Σ ν_i R_p e_i`` on the child."""
    rng = np.random.default_rng(12)
    f = _joint_forces_function(False, False, "prismatic")
    params = _joint_params(rng, f)
    params["axis_p"] = np.cross(params["perp_p"][:, 0], params["perp_p"][:, 1])
    Rp, Rc = _rand_rotation(rng), _rand_rotation(rng)
    pp, pc = rng.standard_normal(3), rng.standard_normal(3)
    tau = rng.standard_normal(1)
    x = {"Rp": Rp, "pp": pp, "Rc": Rc, "pc": pc, "tau": tau}
    got = f.value(x | {"lam": np.zeros(5)}, params)[0]
    r_p, r_c, a_p = params["r_p"], params["r_c"], params["axis_p"]
    a_w = Rp @ a_p
    gap = Rc @ r_c + pc - Rp @ r_p - pp
    expected = -tau[0] * np.concatenate(
        [np.cross(a_p, Rp.T @ gap) - np.cross(r_p, a_p), -a_w, np.cross(r_c, Rc.T @ a_w), a_w]
    )
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)

    # Slide multipliers: a world force on the child along the parent's e_i, its reaction on the
    # parent; all constraint forces together exert no net force and no net moment about the world
    # origin (Newton's third law for the pair).
    lam = rng.standard_normal(5)
    rows = f.value(x | {"lam": lam, "tau": np.zeros(1)}, params)[0]
    np.testing.assert_allclose(rows[9:], -Rp @ params["perp_p"] @ lam[3:], atol=1e-12)
    np.testing.assert_allclose(rows[3:6] + rows[9:], 0.0, atol=1e-12)
    moment = sum(
        R @ rows[i : i + 3] + np.cross(p, rows[i + 3 : i + 6])
        for R, p, i in ((Rp, pp, 0), (Rc, pc, 6))
    )
    np.testing.assert_allclose(moment, 0.0, atol=1e-11)


# ------------------------------------------------------------------------------- warm start


def _simulated(name: str, dt: float, N: int):
    """LGVI run of the smooth scenario and its joint path at knots 0 … N+1."""
    mm = _mm(name)
    q_ref, tau = _reference(name, dt, N)
    traj = simulate_maximal(mm, q_ref[0], q_ref[1], tau, dt, N)
    R = np.concatenate([traj.R, (traj.R[-1] @ traj.F[-1])[None]])
    p = np.concatenate([traj.p, (traj.p[-1] + dt * traj.v[-1])[None]])
    return traj, joint_positions(mm, R, p, q_ref=q_ref[0]), tau


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
    np.testing.assert_allclose(tau_ws[1:], tau[1:], atol=1e-7 * scale)
    lam_ws = point["lam"].reshape(N + 1, mm.nb, 5)
    np.testing.assert_allclose(lam_ws[1:], traj.lam[1:], atol=1e-7 * np.abs(traj.lam).max())
    np.testing.assert_allclose(point["F"].reshape(traj.F.shape), traj.F, atol=1e-12)


@pytest.mark.parametrize("name", ["iiwa", "panda"])
def test_warm_start_from_pinocchio_is_dynamically_consistent(name: str) -> None:
    """Inverse dynamics of the damped LGVI on Pinocchio's damped motion: the knot torques."""
    mm = _mm(name)
    errors = []
    for dt in (0.01, 0.005):
        N = round(0.1 / dt)
        q, tau = _reference(name, dt, N)
        point = maximal_warm_start(mm, q, dt, N=N)
        problem = _problem(mm, N, dt)
        assert np.abs(problem.values(point)[1]).max() <= 1e-8
        tau_ws = point["tau"].reshape(N + 1, mm.nb)[1:]
        errors.append(np.abs(tau_ws - tau[1:]).max() / np.abs(tau).max())
    assert errors[0] < 1e-3
    assert errors[0] / errors[1] > 3.0, errors  # O(Δt²) or better


def test_warm_starts_share_one_dynamics_problem_across_threads() -> None:
    """The dynamics rows' problem is built once per (model, N, Δt) of a workspace and evaluated
    under its lock: warm starts from 4 threads at once equal the sequential ones bit for bit."""
    from concurrent.futures import ThreadPoolExecutor

    import mbplan.simulation.warm_start as ws
    from mbplan.workspace import Workspace

    mm, dt, N = _mm("iiwa"), 0.01, 10
    paths = [_reference("iiwa", dt, N)[0] + 0.01 * i for i in range(8)]
    built = []
    original = ws._DynamicsRows.__init__

    def counted(self, *args) -> None:
        built.append(args)
        original(self, *args)

    shared = Workspace()
    try:
        ws._DynamicsRows.__init__ = counted
        sequential = [maximal_warm_start(mm, q, dt, N=N, workspace=shared) for q in paths]
        with ThreadPoolExecutor(4) as pool:
            parallel = list(
                pool.map(lambda q: maximal_warm_start(mm, q, dt, N=N, workspace=shared), paths)
            )
    finally:
        ws._DynamicsRows.__init__ = original
    assert len(built) == 1
    for a, b in zip(sequential, parallel, strict=True):
        for block in a:
            np.testing.assert_array_equal(a[block], b[block])
    problem = _problem(mm, N, dt)
    assert all(np.abs(problem.values(x)[1]).max() <= 1e-8 for x in sequential)


@pytest.mark.parametrize("dense_max", [0, 10**6])
def test_warm_start_block_solves_agree_and_report_singular_blocks(
    dense_max: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The knot blocks solved by SuperLU (dense_max = 0) or by one batched dense solve give the
    same λ, τ; a singular block is an MbplanError naming the model."""
    import dataclasses

    import mbplan.simulation.warm_start as ws
    from mbplan.workspace import Workspace

    mm, dt, N = _mm("iiwa"), 0.01, 10
    q = _reference("iiwa", dt, N)[0]
    reference = maximal_warm_start(mm, q, dt, N=N)
    monkeypatch.setattr(ws, "DENSE_BLOCK_MAX", dense_max)
    point = maximal_warm_start(mm, q, dt, N=N)
    for block in ("lam", "tau"):
        np.testing.assert_allclose(point[block], reference[block], rtol=1e-9, atol=1e-9)
    shared = Workspace()
    dynamics = ws._dynamics_rows(mm, N, dt, True, shared)
    evaluate = dynamics.problem.evaluate

    def without_torques(*args, **kwargs):  # the τ columns of every block zero: singular
        ev = evaluate(*args, **kwargs)
        jac = ev.eq_jacobian.copy()
        tau = dynamics.variables.tangent_index("tau").ravel()
        jac.data[np.isin(jac.indices, tau)] = 0.0
        return dataclasses.replace(ev, eq_jacobian=jac)

    monkeypatch.setattr(dynamics.problem, "evaluate", without_torques)
    with pytest.raises(MbplanError, match=r"iiwa.*cannot balance"):
        maximal_warm_start(mm, q, dt, N=N, workspace=shared)


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
    s = validate_dynamics.run(("double_pendulum_continuous",), 0, tmp_path, (0.004, 0.002), 0.02)
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["dt"] == [0.004, 0.002] and saved["command"] == s["command"]
    assert [c["damping"] for c in saved["cases"]] == ["undamped", "damped"]
    for case in saved["cases"]:
        assert case["joints"] == {"continuous": 2}
        assert len(case["runs"]) == 2 and case["observed_order"] is not None
        assert max(r["max_constraint_residual"] for r in case["runs"]) <= 1e-10
    assert (tmp_path / "results.md").read_text().startswith("# LGVI")
    assert (tmp_path / "validate_dynamics.png").stat().st_size > 0
    with pytest.raises(InputError, match=r"dt=0\.003"):
        validate_dynamics.run(("iiwa",), 0, tmp_path, (0.003, 0.002), 0.02)


def test_chain_scaling_writes_its_results(tmp_path) -> None:
    s = chain_scaling.run(tmp_path, bodies=(1, 3), N=4)
    assert [r["bodies"] for r in s["rows"]] == [1, 3]
    assert all(r["max_residual_at_point"] <= 1e-8 for r in s["rows"])
    assert set(s["ratio_last_over_first"]) == {"bodies", "value", "jacobian", "hessian"}
    assert (tmp_path / "chain_scaling.png").stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["N"] == 4
