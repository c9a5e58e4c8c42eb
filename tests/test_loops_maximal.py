"""Loop closures in maximal coordinates: the closures' bodies and frames, exact derivatives of
their forces and constraints, the LGVI with closures against Pinocchio's constrained dynamics,
the warm start and the RIPM (full and reduced KKT) on a four-bar."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from loop_mechanisms import fourbar, fourbar_path, spatial_branches, spatial_chain

from mbplan import OCP
from mbplan.benchmarks import validate_dynamics
from mbplan.benchmarks.validate_dynamics import validate_case
from mbplan.engine import check_derivatives
from mbplan.errors import InputError, WarmStartWarning
from mbplan.formulations.maximal import MaximalNLP, _maximal
from mbplan.formulations.maximal_layout import maximal_layout
from mbplan.lie import SO3
from mbplan.multibody import body_poses, maximal_model
from mbplan.multibody.loops import loop_residuals
from mbplan.planning.initial_guess import (
    closed_path,
    goal_configuration,
    initial_path,
    path_clearance,
)
from mbplan.planning.solve import plan
from mbplan.residuals import JointPosition, JointTorque, JointVelocity
from mbplan.robots.loops import (
    LOOP_KINDS,
    Loop,
    closure_jacobian,
    closure_residual,
    loop_jacobian,
)
from mbplan.simulation import simulate_maximal
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem
from mbplan.solvers.kkt.system import Inertia, KKTSystem
from mbplan.taskfile import load_task
from mbplan.tasks.speed import maximal_ripm_problem
from mbplan.transcription.loops import (
    loop_constraint_function,
    loop_forces_function,
    stack_multipliers,
)
from mbplan.transcription.multibody import multibody_layout
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import TrajectoryVariables

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "tasks"

SPATIAL = {"point": 4, "revolute": 6, "weld": 7}  # joints: one degree of freedom each
BRANCHES = (("point", 4), ("revolute", 6), ("point", 4))  # two loops share a multiplier block


def _mechanism(name: str):
    if name == "fourbar":
        return fourbar()
    return spatial_branches(BRANCHES) if name == "branches" else spatial_chain(name, SPATIAL[name])


def _rotation(rng: np.random.Generator) -> np.ndarray:
    return SO3.exp(rng.normal(size=3))


# ------------------------------------------------------------------------------ the model


@pytest.mark.parametrize("kind", sorted(SPATIAL))
def test_closure_rows_on_body_poses_equal_the_joint_space_residual(kind: str) -> None:
    rng = np.random.default_rng(1)
    for robot in (fourbar(), spatial_chain(kind, SPATIAL[kind])):
        mm = maximal_model(robot)
        assert [lp.name for lp in mm.loops] == [loop.name for loop in robot.loops]
        q = rng.uniform(-1.0, 1.0, (3, robot.nq))
        R, p = body_poses(mm, q)
        expected = [closure_residual(robot.model, robot.loops, qk) for qk in q]
        np.testing.assert_allclose(loop_residuals(mm.loops, R, p), expected, atol=1e-14)
    world = spatial_chain(kind, SPATIAL[kind])
    assert maximal_model(world).loops[0].body2 == -1  # joint "universe": the world


def test_loop_jacobian_equals_central_differences() -> None:
    rng = np.random.default_rng(2)
    model = spatial_chain("point", 7).model
    for kind in LOOP_KINDS:
        for joint2 in ("b0j5", "universe"):
            frames = []
            for _ in range(2):
                M = np.eye(4)
                M[:3, :3], M[:3, 3] = _rotation(rng), 0.1 * rng.normal(size=3)
                frames.append(M)
            loop = Loop("a", kind, "b0j2", frames[0], joint2, frames[1], LOOP_KINDS[kind])
            q = rng.uniform(-1.0, 1.0, model.nq)
            J = loop_jacobian(model, [loop], q)
            np.testing.assert_allclose(J, closure_jacobian(model, [loop], q), atol=1e-8)


def test_models_of_one_pinocchio_model_with_other_loops_differ() -> None:
    robot = fourbar()
    closed = _maximal(robot.model, robot.loops)
    assert closed is _maximal(robot.model, robot.loops)
    assert _maximal(robot.model, ()).loops == () and len(closed.loops) == 1
    moved = replace(robot.loops[0], placement2=robot.loops[0].placement1)
    assert _maximal(robot.model, (moved,)) is not closed


def test_a_loop_the_maximal_model_cannot_hold_is_an_input_error() -> None:
    robot = fourbar()
    loop = robot.loops[0]
    with pytest.raises(InputError, match="kind 'hinge'"):
        maximal_model(robot.model, [replace(loop, kind="hinge")])
    with pytest.raises(InputError, match="'elbow' is not a joint"):
        maximal_model(robot.model, [replace(loop, joint2="elbow")])
    with pytest.raises(InputError, match="rows \\['rz'\\]"):
        maximal_model(robot.model, [replace(loop, components=("x", "rz"))])
    with pytest.raises(InputError, match="both frames"):
        maximal_model(robot.model, [replace(loop, joint2=loop.joint1)])


# --------------------------------------------------------------------------- derivatives


def _groups() -> list[tuple[str, tuple[int, ...], bool, bool]]:
    out = []
    for kind, names in LOOP_KINDS.items():
        rows = tuple(range(len(names)))
        out += [(kind, rows, False, False), (kind, rows[1:], True, False)]
        out.append((kind, rows[:-1], False, True))
    return out


def _group_id(group: tuple[str, tuple[int, ...], bool, bool]) -> str:
    kind, rows, world1, world2 = group
    return f"{kind}{''.join(map(str, rows))}{'_world1' * world1}{'_world2' * world2}"


@pytest.mark.parametrize("what", ["forces", "constraints"])
@pytest.mark.parametrize("group", _groups(), ids=_group_id)
def test_loop_terms_derivatives_match_finite_differences(group, what: str) -> None:
    """Along the retraction ``R exp(ξ)``, ``p + ξ`` (interpreted functions; Δt = 0.5)."""
    rng = np.random.default_rng(3)
    factory = loop_forces_function if what == "forces" else loop_constraint_function
    f = factory(False, group)
    params = {"Rf1": _rotation(rng), "r1": rng.normal(size=3)}
    params |= {"Rf2": _rotation(rng), "r2": rng.normal(size=3)}
    if what == "constraints":
        params["dt"] = 0.5
    for _ in range(3):
        x = {
            s.name: _rotation(rng) if s.shape == (3, 3) else rng.normal(size=s.shape)
            for s in f.variables
        }
        check = check_derivatives(f, x, params, rng=rng)
        assert check.ok(1e-6), (f.name, check)


def test_loop_forces_are_the_closure_jacobian_transpose() -> None:
    """A world closure's force on its body, mapped to the joints through Pinocchio's Jacobians
    of the body's COM velocity (world) and spin (body frame), is ``J_loop(q)ᵀλ``: the LGVI's
    force is the closure's constraint force."""
    robot = spatial_chain("weld", 7)
    mm, model = maximal_model(robot), robot.model
    rng = np.random.default_rng(4)
    q, lam = rng.uniform(-1.0, 1.0, model.nq), rng.normal(size=6)
    R, p = body_poses(mm, q)
    lp = mm.loops[0]
    f = loop_forces_function(False, lp.group)
    params = {"Rf1": lp.Rf1, "r1": lp.r1, "Rf2": lp.Rf2, "r2": lp.r2}
    rows = f.value({"R1": R[lp.body1][None], "p1": p[lp.body1][None], "lam": lam[None]}, params)
    torque, force = -rows[0, :3], -rows[0, 3:]  # the body's torque (body frame), force (world)
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    joint, com = int(mm.pin_joint[lp.body1]), pin.SE3(np.eye(3), mm.com_in_joint[lp.body1])
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    velocity = pin.getFrameJacobian(model, data, joint, com, world)[:3]  # COM, world frame
    spin = pin.getJointJacobian(model, data, joint, pin.ReferenceFrame.LOCAL)[3:]  # body frame
    generalized = velocity.T @ force + spin.T @ torque
    expected = loop_jacobian(model, robot.loops, q).T @ lam
    np.testing.assert_allclose(generalized, expected, atol=1e-12)


# ------------------------------------------------------------------- LGVI vs Pinocchio


@cache
def _case(name: str, damping: float = 0.0) -> dict:
    robot = _mechanism(name)
    model = robot.model.copy()
    model.damping[:] = damping
    return validate_case(model, 0, (0.004, 0.002, 0.001), 0.2, None, robot.loops, robot.passive)


CASES = [("fourbar", 0.0), ("fourbar", 0.1), *((n, 0.0) for n in (*SPATIAL, "branches"))]


@pytest.mark.parametrize(("name", "damping"), CASES)
def test_lgvi_with_closures_converges_to_pinocchio_with_order_two(
    name: str, damping: float
) -> None:
    case = _case(name, damping)
    assert 1.8 <= case["observed_order"] <= 2.2, case
    assert case["runs"][-1]["max_joint_error"] <= 1e-3
    assert max(r["max_closure_residual"] for r in case["runs"]) <= 1e-11  # round-off
    assert case["euler_observed_order"] < 1.5  # the check tells a first-order method apart


def test_simulation_keeps_the_closures_at_round_off() -> None:
    robot = fourbar()
    mm = maximal_model(robot)
    q0 = robot.closed(np.array([0.3, 0.0, 0.0]))
    traj = simulate_maximal(mm, q0, q0, np.zeros(3), 0.01, 50)  # falls under gravity
    assert np.abs(loop_residuals(mm.loops, traj.R, traj.p)).max() <= 1e-12
    assert (
        np.abs(traj.R[-1] - body_poses(mm, q0)[0]).max() > 0.1
        and np.abs(traj.loop_lam[1:]).min() > 0.0
    )
    with pytest.raises(InputError, match="q1 does not close the loops"):
        simulate_maximal(mm, q0, q0 + np.array([0.0, 0.1, 0.0]), np.zeros(3), 0.01, 5)


# ---------------------------------------------------------------------------- warm start


@pytest.mark.parametrize("name", ["fourbar", "branches"])
def test_warm_start_balances_the_dynamics_with_closure_forces_and_passive_joints(name) -> None:
    """One actuator per degree of freedom, so every knot's block is square and the dynamics rows
    vanish with zero passive torques (the branches: loops of two sizes, not in size order)."""
    robot = _mechanism(name)
    mm, dt, N = maximal_model(robot), 0.02, 6
    active = np.setdiff1d(np.arange(robot.nq), robot.joint_indices(robot.passive))
    end = robot.closed(np.zeros(robot.nq))
    end[active] -= 0.1
    q = closed_path(robot, np.linspace(robot.closed(np.zeros(robot.nq)), end, N + 1))
    passive = tuple(mm.joint_names.index(j) for j in robot.passive)
    point = maximal_warm_start(mm, q, dt, jit=True, passive=passive)
    layout = multibody_layout(mm, N, dt, jit=True)
    problem = TrajectoryProblem(TrajectoryVariables(layout.blocks), layout.terms)
    assert np.abs(problem.values(point)[1]).max() <= 1e-9
    np.testing.assert_array_equal(point["tau"][:, list(passive)], 0.0)
    assert np.abs(stack_multipliers(mm, point, N + 1)[1:]).max() > 0.0
    free = maximal_warm_start(mm, q, dt, jit=True)  # every joint actuated: least squares
    assert np.abs(problem.values(free)[1]).max() <= 1e-9
    with pytest.raises(InputError, match="passive"):
        maximal_warm_start(mm, q, dt, passive=(mm.nb,))


def test_warm_start_paths_close_the_loops_and_head_for_the_partial_goal() -> None:
    robot = fourbar()
    ocp = OCP(robot, N=8, dt=0.05, q0=np.zeros(3))
    ocp.add_terminal_constraint("rocker", JointPosition(joints=["rocker_joint"], target=[0.3]))
    goal = goal_configuration(ocp)
    assert goal[2] == pytest.approx(0.3, abs=1e-12)
    far = OCP(robot, N=8, dt=0.05, q0=np.zeros(3))
    far.add_terminal_constraint("rocker", JointPosition(joints=["rocker_joint"], target=[2.5]))
    with pytest.warns(WarmStartWarning, match="do not close"):
        np.testing.assert_array_equal(goal_configuration(far), far.q0)
    path = initial_path(ocp, "linear")
    assert max(np.abs(closure_residual(robot.model, robot.loops, q)).max() for q in path) <= 1e-9
    np.testing.assert_allclose(path[:, 0], np.r_[0.0, np.linspace(0.0, goal[0], 8)], atol=1e-12)
    np.testing.assert_allclose(path[-1], goal, atol=1e-8)


def test_warm_start_of_a_frame_goal_closes_the_loops_and_reaches_the_goal() -> None:
    """The inverse kinematics takes the closures as rows; a "via" path is closed at every knot
    and clear of the obstacle (the delta's straight path collides with the box)."""
    for name in ("two_arm_carry", "delta_obstacle"):
        ocp = load_task(EXAMPLES / f"{name}.toml", {"horizon.N": 12}).ocp
        robot, goal = ocp.robot, ocp["goal"].residual
        path = initial_path(ocp, "via")
        gaps = [np.abs(closure_residual(robot.model, robot.loops, q)).max() for q in path]
        assert max(gaps) <= 1e-9
        assert path_clearance(ocp, path) <= 0.0
        np.testing.assert_allclose(path[-1], goal_configuration(ocp), atol=1e-6)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, path[-1])
        M = data.oMf[robot.frame_id(goal.frame)]
        np.testing.assert_allclose(M.translation, goal.translation, atol=1e-6)


# ----------------------------------------------------------------------------- the RIPM


def _fourbar_task(N: int) -> OCP:
    ocp = OCP(fourbar(), N=N, dt=0.05, q0=np.zeros(3))
    ocp.add_terminal_constraint("rocker", JointPosition(joints=["rocker_joint"], target=[0.3]))
    ocp.add_terminal_constraint("still", JointVelocity(joints=["crank_joint"], target=[0.0]))
    return ocp.add_cost("effort", JointTorque(joints=["crank_joint"]))


def _branches_task(N: int) -> OCP:
    """Each branch's actuated joint to a goal (a branch without one would fall freely)."""
    ocp = OCP(_mechanism("branches"), N=N, dt=0.05)
    actuated = [f"b{b}j0" for b in range(len(BRANCHES))]
    goal = JointPosition(joints=actuated, target=[0.1, 0.1, 0.1])
    return ocp.add_terminal_constraint("goal", goal).add_cost(
        "effort", JointTorque(joints=actuated)
    )


@pytest.mark.parametrize("task", [_fourbar_task, _branches_task])
def test_reduced_kkt_with_closures_equals_the_full_factorization(task) -> None:
    """Closure rows stay in the reduced matrix and their multipliers join the first wrench block
    of their knot: the inertia of the full LDLᵀ (and the dense eigenvalues), a step that
    solves the full system."""
    problem, x0 = maximal_ripm_problem(task(6), "linear")
    rng = np.random.default_rng(5)
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), np.ones(problem.n_ineq))
    blocks = (ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    lay = maximal_layout(problem, ev.eq_jacobian)
    plan_ = problem.elimination_plan(ev.eq_jacobian)
    wrench = plan_.block_cols[-lay.N * lay.nb :: lay.nb]  # the first wrench block of each knot
    assert all(np.isin(lay.loop_cols[k + 1], wrench[k]).all() for k in range(lay.N))
    n, me, mi = problem.n, problem.n_eq, problem.n_ineq
    full = KKTSystem(n, me, mi)
    red = ReducedKKTSystem(n, me, mi, problem.elimination_plan, strict=True)
    for kkt in (full, red):
        kkt.set_matrices(*blocks)
    for delta_w in (1e-4, 1e-2):
        diag = np.concatenate([np.full(n, delta_w), np.zeros(me + mi)])
        inertia = red.factorize(diag, 1e-9)
        assert inertia == full.factorize(diag, 1e-9)
        eig = np.linalg.eigvalsh(full.matrix().toarray())
        assert inertia == Inertia(int(np.sum(eig > 0)), int(np.sum(eig < 0)), 0)
        b = rng.normal(size=n + me + mi)
        x, ratio = red.solve(b)
        assert ratio <= 1e-10  # backward stable (the LGVI's KKT is ill-conditioned: cond ~1e9)
        assert np.abs(full.matvec(x) - b).max() <= 1e-9 * (np.abs(x).max() + np.abs(b).max())
    assert red.n_reduced == 2 and red.n_fallbacks == 0 and red.reduction.nr < n


@pytest.mark.parametrize("kkt_method", ["full", "reduced"])
@pytest.mark.parametrize("task", [_fourbar_task, _branches_task])
def test_ripm_plans_on_the_closures(task, kkt_method: str) -> None:
    ocp = task(20)
    result = plan(ocp, "ripm", warm_start="linear", tol=1e-9, options={"kkt_method": kkt_method})
    assert result.success, result.message  # the goal and the passive joints' zero torque met
    robot = ocp.robot
    gaps = [np.abs(closure_residual(robot.model, robot.loops, q)).max() for q in result.q]
    assert max(gaps) <= 1e-9
    passive = robot.joint_indices(robot.passive)
    np.testing.assert_allclose(result.tau_knots[:, passive], 0.0, atol=1e-8)
    if task is _fourbar_task:
        assert result.q[-1, 2] == pytest.approx(0.3, abs=1e-9)
        assert abs(result.q[-1, 0]) > 0.5  # the crank drove it there
        assert MaximalNLP(ocp, jit=True).passive == (1, 2)


def test_ripm_plans_the_two_arm_carry_at_rest_in_few_iterations() -> None:
    """Rest on the independent joints and a closed warm start at the goal: a handful of
    iterations (500 without convergence when rest was imposed on all 12 joints)."""
    task = load_task(EXAMPLES / "two_arm_carry.toml", {"horizon.N": 12, "horizon.dt": 1 / 6})
    result = plan(task.ocp, "ripm", warm_start=task.warm_start, tol=task.tol)
    assert result.success and result.iterations <= 10, (result.status, result.iterations)
    assert np.abs(result.v[-1]).max() <= 1e-9  # every joint at rest


def test_validate_dynamics_covers_loop_mechanisms(tmp_path) -> None:
    path = str(fourbar_path())
    s = validate_dynamics.run((path,), 0, tmp_path, (0.004, 0.002), 0.02)
    assert [c["damping"] for c in s["cases"]] == ["undamped", "damped"]
    for case in s["cases"]:
        assert case["loops"] == [fourbar().loops[0].describe()]
        assert max(r["max_closure_residual"] for r in case["runs"]) <= 1e-10
    assert "point closure 'coupler_joint' - 'rocker_joint'" in (tmp_path / "results.md").read_text()
