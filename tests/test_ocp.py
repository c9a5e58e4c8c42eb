"""The OCP API: every residual kind × every formulation against finite differences (along the
retraction in maximal coordinates), serialisation, bad input named before any solve."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives, check_problem_derivatives

import mbplan as mb
from mbplan import residuals as res
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.maximal import MaximalNLP
from mbplan.planning.initial_guess import inverse_kinematics
from mbplan.tasks.paper import IIWA_START
from mbplan.transcription.intervals import INTERVAL_ROWS

GOAL = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 0.5), np.array([0.4, 0.1, 0.6]))


def factory_ocp(distance: bool) -> mb.OCP:
    """Every residual kind, as a cost where it can be one and as a constraint."""
    scene = mb.Scene().add_cylinder("post", 0.08, 1.0, (0.55, -0.35, 0.5))
    scene.add_box("box", (0.1, 0.1, 0.1), (0.0, 0.6, 0.6))
    ocp = mb.OCP("iiwa", scene, N=3, dt=0.05, q0=IIWA_START)
    target = np.linspace(-0.5, 0.5, 7)
    ocp.add_cost("q", res.JointPosition(target), 1.3)
    ocp.add_cost("v", res.JointVelocity(), 0.1)
    ocp.add_cost("tau", res.JointTorque(np.full(7, 2.0)), 1e-3)
    ocp.add_cost("pose", res.FramePlacement("iiwa_link_7", GOAL), 2.0)
    ocp.add_cost("point", res.FrameTranslation("iiwa_link_5", [0.3, 0.2, 0.5]), 1.5)
    ocp.add_constraint("q_eq", res.JointPosition([0.2], joints=("iiwa_joint_2",)), knots=[2])
    ocp.add_constraint(
        "v_eq", res.JointVelocity([0.1, -0.1], ("iiwa_joint_1", "iiwa_joint_4")), [1]
    )
    ocp.add_constraint("tau_eq", res.JointTorque([1.0], ("iiwa_joint_3",)), knots=[1])
    ocp.add_terminal_constraint("pose_eq", res.FramePlacement("iiwa_link_ee", GOAL))
    ocp.add_constraint("point_eq", res.FrameTranslation("iiwa_link_4", [0.1, 0.0, 0.7]), [2])
    ocp.add_constraint("com", res.ComOutsideCylinder("post", 0.02))
    ocp.add_cost("com_goal", res.ComPosition([0.1, 0.0, 0.5]), 0.7)
    ocp.add_constraint("com_eq", res.ComPosition([0.0, 0.01, 0.45]), knots=[3])
    ocp.add_constraint("above", res.FrameHeight("iiwa_link_6", 0.3))
    ocp.add_constraint("coupling", res.JointCoupling("iiwa_joint_6", "iiwa_joint_5", -0.5, 0.1))
    ocp.add_constraint("q_limits", res.JointPositionLimits())
    ocp.add_constraint("v_limits", res.JointVelocityLimits())
    ocp.add_constraint("tau_limits", res.JointTorqueLimits())
    if distance:
        ocp.add_constraint("clearance", res.Distance(0.01))
    return ocp


PANDA_START = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.79, 0.01, 0.01])
FINGERS = ("panda_finger_joint1", "panda_finger_joint2")


def panda_ocp() -> mb.OCP:
    """Every joint residual kind on the panda with its two prismatic fingers not locked."""
    ocp = mb.OCP("panda", N=3, dt=0.05, q0=PANDA_START)
    target = PANDA_START + np.r_[np.full(7, 0.2), 0.01, 0.015]
    ocp.add_cost("q", res.JointPosition(target), 1.3)
    ocp.add_cost("v", res.JointVelocity(), 0.1)
    ocp.add_cost("tau", res.JointTorque(), 1e-3)
    ocp.add_constraint("fingers", res.JointPosition([0.02, 0.025], joints=FINGERS), knots=[2])
    ocp.add_constraint("finger_v", res.JointVelocity([0.05], FINGERS[:1]), knots=[1])
    ocp.add_constraint("finger_force", res.JointTorque([1.0], FINGERS[1:]), knots=[1])
    ocp.add_terminal_constraint("hand", res.FrameTranslation("panda_leftfinger", [0.3, 0.0, 0.5]))
    ocp.add_constraint("q_limits", res.JointPositionLimits())
    ocp.add_constraint("v_limits", res.JointVelocityLimits())
    ocp.add_constraint("tau_limits", res.JointTorqueLimits())
    return ocp


@pytest.mark.parametrize("distance", [False, True])
def test_generalized_derivatives_match_finite_differences(distance: bool) -> None:
    ocp = factory_ocp(distance)
    nlp = GeneralizedNLP(ocp)
    rng = np.random.default_rng(0)
    q = np.linspace(ocp.q0, np.zeros(7), ocp.N + 1)
    z = nlp.initial_guess(q) + 0.05 * rng.standard_normal(nlp.n)
    lam = rng.standard_normal(nlp.m)
    for block in nlp.own:  # fixed-witness-point Hessian: tested in test_collision
        if isinstance(block.item.residual, res.Distance):
            lam[block.row0 : block.row0 + block.size] = 0.0
    check_generalized_derivatives(nlp, z, lam)
    between = 3 * INTERVAL_ROWS  # rows between knots: 3 intervals, a secant's ends, its centre
    com, pairs = 7, 7 * 2
    knots = 2 * 3 * 7 + 1 + 2 + 1 + 6 + 3 + 3 + (3 + between) * com + 3 + 3  # com_eq, above
    assert nlp.m == knots + ((3 + between) * pairs if distance else 0)


@pytest.mark.parametrize("case", ["iiwa", "iiwa-distance", "panda"])
def test_maximal_derivatives_match_finite_differences_along_the_retraction(case: str) -> None:
    distance = case == "iiwa-distance"
    ocp = panda_ocp() if case == "panda" else factory_ocp(distance)
    nlp = MaximalNLP(ocp, jit=False)
    prob = nlp.problem
    rng = np.random.default_rng(1)
    goal = np.zeros(ocp.robot.nq) if case != "panda" else PANDA_START + 0.1
    x = nlp.initial_point(np.linspace(ocp.q0, goal, ocp.N + 1))
    x = prob.retract(x, 0.05 * rng.standard_normal(prob.n))
    check_problem_derivatives(prob, x, rng, ineq_hessian=not distance)


def test_both_formulations_write_the_same_residuals() -> None:
    """At a joint path, every constraint of the maximal NLP vanishes where the joint-space
    residual does: the terminal pose constraint equals the joint-space frame error."""
    ocp = factory_ocp(False)
    nlp = MaximalNLP(ocp, jit=False)
    q = np.linspace(ocp.q0, np.zeros(7), ocp.N + 1)
    x = nlp.initial_point(q)
    from mbplan.formulations.joint_space import evaluate

    item = ocp["pose_eq"]
    expected = evaluate(ocp.robot, ocp.scene, item.residual, q[-1:], q[-1:], None)[0]
    term = next(t for t in nlp.problem.terms if t.name == "pose_eq")
    flat = {n: nlp.problem.variables.blocks[n].flat(a) for n, a in x.items()}
    value = term.function.value(term.gather(flat), term.parameters)
    np.testing.assert_allclose(np.ravel(value), expected, atol=1e-9)
    assert np.linalg.norm(expected) > 0.1


def test_prismatic_residuals_equal_the_joint_space_ones() -> None:
    """Finger positions, velocities (central difference) and limits in maximal coordinates read
    the same numbers as in joint space; the joint path round-trips through the bodies' poses."""
    ocp = panda_ocp()
    nlp = MaximalNLP(ocp, jit=False)
    s = np.linspace(0.0, 1.0, ocp.N + 1)[:, None] ** 2  # accelerating: steps differ
    q = ocp.q0 + s * (PANDA_START + np.r_[np.full(7, 0.1), 0.02, 0.01] - ocp.q0)
    x = nlp.initial_point(q)
    np.testing.assert_allclose(nlp.joint_trajectory(x)["q"], q, atol=1e-12)
    flat = {n: nlp.problem.variables.blocks[n].flat(a) for n, a in x.items()}

    def value(name: str) -> np.ndarray:
        term = next(t for t in nlp.problem.terms if t.name == name)
        return np.ravel(term.function.value(term.gather(flat), term.parameters))

    np.testing.assert_allclose(value("fingers_prismatic"), q[2, 7:] - [0.02, 0.025], atol=1e-12)
    central = (q[2, 7] - q[0, 7]) / (2 * ocp.dt)  # the velocity a plan reports at knot 1
    assert abs(central - (q[2, 7] - q[1, 7]) / ocp.dt) > 1e-3
    np.testing.assert_allclose(value("finger_v_prismatic"), [central - 0.05], atol=1e-10)
    lo, hi = ocp.robot.model.lowerPositionLimit[7:], ocp.robot.model.upperPositionLimit[7:]
    limits = value("q_limits_prismatic").reshape(ocp.N, 2, 2)  # knots 1..N, fingers, (lo, hi)
    np.testing.assert_allclose(limits[:, :, 0], lo - q[1:, 7:], atol=1e-12)
    np.testing.assert_allclose(limits[:, :, 1], q[1:, 7:] - hi, atol=1e-12)


def test_panda_with_prismatic_fingers_plans_in_maximal_coordinates_and_verifies() -> None:
    """The panda with its fingers not locked, the RIPM on SO(3)×R³ bodies, Pinocchio's verifier."""
    from mbplan.tasks.paper import tracking_ocp

    goal = np.array([0.4, -0.1, 0.1, -1.9, 0.0, 2.1, 0.6, 0.03, 0.03])
    ocp = tracking_ocp("panda", PANDA_START, goal, N=8, dt=0.06)
    result = mb.plan(ocp, "ripm")
    assert result.success, result.message
    check = mb.verify(ocp, result)
    assert check.passed, check.reasons
    assert np.all(np.abs(result.q[-1, 7:] - goal[7:]) < 0.005)  # the fingers moved 2 cm


def test_rest_at_the_goal_plans_in_both_formulations() -> None:
    """A terminal velocity equality means the velocity the plan reports and the verifier checks
    (maximal coordinates: the central difference; it was the forward step, which left the RIPM
    plan moving at 0.87 rad/s at the last knot)."""
    qT = np.array([0.5, 0.3, 0.0, -0.5, 0.0, 0.4, 0.0])
    ocp = mb.OCP(mb.load_robot("iiwa", damping=False), N=20, dt=0.05, q0=np.zeros(7))
    ocp.add_cost("effort", res.JointTorque(), 1e-3).add_cost("v", res.JointVelocity(), 1e-2)
    ocp.add_constraint("q_limits", res.JointPositionLimits())
    ocp.add_constraint("v_limits", res.JointVelocityLimits())
    ocp.add_terminal_constraint("goal", res.JointPosition(qT))
    ocp.add_terminal_constraint("rest", res.JointVelocity())
    for method in ("ripm", "ipopt"):
        plan = mb.plan(ocp, method)
        assert plan.success, (method, plan.message, plan.violations)
        assert np.max(np.abs(plan.v[-1])) < 1e-6, method
        assert mb.verify(plan).passed, method


def test_ocp_round_trips_through_json() -> None:
    ocp = factory_ocp(True)
    again = mb.OCP.from_dict(ocp.to_dict())
    assert again.names == ocp.names and again.scene.names == ocp.scene.names
    for a, b in zip(ocp.items, again.items, strict=True):
        assert a.residual.to_dict() == b.residual.to_dict()
        assert np.array_equal(a.knots, b.knots) and a.weight == b.weight


def test_bad_input_is_named_before_any_solve() -> None:
    ocp = mb.OCP("iiwa", N=4)
    with pytest.raises(mb.InputError, match="no frame 'hand'"):
        ocp.add_cost("x", res.FrameTranslation("hand", [0, 0, 0]))
    with pytest.raises(mb.InputError, match="no joint 'elbow'"):
        ocp.add_cost("x", res.JointPosition([0.0], joints=("elbow",)))
    with pytest.raises(mb.InputError, match="NaN"):
        ocp.add_cost("x", res.JointPosition(np.full(7, np.nan)))
    with pytest.raises(mb.InputError, match="q0: contains NaN"):
        mb.OCP("iiwa", q0=np.full(7, np.nan))
    with pytest.raises(mb.InputError, match="can only be a constraint"):
        ocp.add_cost("x", res.Distance(0.01))
    with pytest.raises(mb.InputError, match="no object"):
        ocp.add_constraint("x", res.ComOutsideCylinder("nothing", 0.0))
    bare = pin.buildModelFromUrdf(
        str(mb.load_robot("iiwa").source.get("path", "robots/iiwa14.urdf"))
    )
    no_geometry = mb.OCP(bare, mb.Scene().add_sphere("s", 0.1, (0.5, 0, 0.5)))
    with pytest.raises(mb.InputError, match="no collision geometry"):
        no_geometry.add_constraint("x", res.Distance(0.01))
    far = pin.SE3(np.eye(3), np.array([3.0, 0.0, 0.5]))
    with pytest.raises(mb.InfeasibleRequestError, match="out of reach"):
        inverse_kinematics(
            ocp.robot, res.FramePlacement("iiwa_link_ee", far).resolve(ocp.robot, ocp.scene), ocp.q0
        )
    blocked = mb.OCP("iiwa", mb.Scene().add_sphere("s", 0.2, (0.0, 0.0, 0.4)), N=4)
    blocked.add_constraint("clearance", res.Distance(0.01))
    with pytest.raises(mb.InfeasibleRequestError, match=r"'clearance'.*scene object 's'"):
        mb.plan(blocked, "ipopt")
    with pytest.raises(mb.InputError, match="unknown method"):
        mb.plan(factory_ocp(False), "newton")
    velocity = mb.OCP("iiwa", N=4).add_cost("v", res.JointVelocity(np.ones(7)))
    with pytest.raises(mb.InputError, match=r"maximal formulation.*'v'.*nonzero target"):
        mb.plan(velocity, "ripm")


def test_inverse_kinematics_reaches_a_goal_whose_solution_lies_on_a_joint_limit() -> None:
    """The SO-100's jaw at a pose reached with its second joint on its lower limit: damped least
    squares with clipped steps stalls there from every start (error 1.35); the bounded
    least-squares polish reaches it."""
    import pinocchio as pin

    from mbplan.planning import initial_guess
    from mbplan.residuals import FramePlacement
    from mbplan.tasks.robustness import sweep_robot

    robot = sweep_robot("so100")
    q_goal = np.array([-0.038, 0.0, -2.3457, -0.8604, -1.5967, 0.3223])
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q_goal)
    goal = FramePlacement("jaw", data.oMf[robot.model.getFrameId("jaw")])
    q_init = np.array([0.359, 0.897, -1.478, -1.421, -1.478, 0.799])
    q = initial_guess.inverse_kinematics(robot, goal, q_init)
    data_q = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data_q, q)
    reached = data_q.oMf[robot.model.getFrameId("jaw")]
    assert np.linalg.norm(pin.log6(goal.placement.actInv(reached)).vector) < 1e-6
    assert np.all(q >= robot.model.lowerPositionLimit) and np.all(
        q <= robot.model.upperPositionLimit
    )
