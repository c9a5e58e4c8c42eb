"""Quadruped and biped gaits as OCPs: Crocoddyl's schedules phase by phase, a trot planned
with hard contacts and verified, and inputs refused by name."""

from __future__ import annotations

import numpy as np
import pytest

import mbplan as mb
from mbplan.errors import InputError
from mbplan.formulations import maximal
from mbplan.formulations.maximal_velocity_limits import SLACK, tighten_velocity_limits
from mbplan.locomotion import QUADRUPED_GAITS, biped_gait, quadruped_gait
from mbplan.ocp.contacts import frame_position
from mbplan.tasks.locomotion import gait_case

FEET = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")


def _contact_sets(ocp: mb.OCP) -> list[list[str]]:
    """The feet on the ground over each interval (held at both of its knots)."""
    return [
        sorted(c.frame for c in ocp.contacts if c.first <= k and k + 1 <= c.last)
        for k in range(ocp.N)
    ]


@pytest.mark.parametrize("gait", sorted(QUADRUPED_GAITS))
def test_the_schedules_are_crocoddyl_s_phase_by_phase(gait: str) -> None:
    """Every running model of Crocoddyl's gait but its impulse models, in order: the same feet
    in contact over the same intervals; then one support interval more."""
    pytest.importorskip("crocoddyl")
    from crocoddyl.utils.quadruped import SimpleQuadrupedalGaitProblem

    robot = mb.load_robot("solo12")
    q0 = robot.configuration("standing")
    x0 = np.concatenate([q0, np.zeros(robot.nv)])
    builder = SimpleQuadrupedalGaitProblem(robot.model, *FEET)
    if gait == "jump":
        problem = builder.createJumpingProblem(x0, 0.1, np.array([0.2, 0.0, 0.0]), 0.01, 3, 5)
    else:
        names = {"walk": "Walking", "trot": "Trotting", "pace": "Pacing", "bound": "Bounding"}
        problem = getattr(builder, f"create{names[gait]}Problem")(x0, 0.15, 0.1, 0.01, 5, 3)
    expected = [
        sorted(name.removesuffix("_contact") for name in m.differential.contacts.active_set)
        for m in problem.runningModels
        if hasattr(m, "differential")
    ]
    ocp = quadruped_gait(robot, FEET, gait, step_knots=5, support_knots=3)
    assert _contact_sets(ocp) == [*expected, list(FEET)]


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_a_trot_is_planned_with_hard_cones_and_the_replay_verifies_it(method: str) -> None:
    ocp = quadruped_gait("solo12", gait="trot", step_length=0.1, step_height=0.05, dt=0.02,
                         step_knots=8, support_knots=2)  # fmt: skip
    assert ocp.N == 21 and len(ocp.contacts) == 8
    result = mb.plan(ocp, method, warm_start="linear")
    assert result.success, result.message
    check = mb.verify(result)
    assert check.passed, check.reasons
    assert 0.06 < result.q[-1, 0] - result.q[0, 0] < 0.09  # the COM: (0.05 + 0.1) / 2 ahead
    assert max(check.violations[f"{c.name}.cone"] for c in ocp.contacts) < 1e-6
    foot = ocp.robot.frame_id("FR_FOOT")
    z = np.array([frame_position(ocp.robot.model, foot, q)[2] for q in result.q[3:10]])
    assert z.max() > ocp.contacts[0].position[2] + 0.02  # the swing foot lifts


def test_gait_inputs_are_refused_by_name() -> None:
    with pytest.raises(InputError, match="expected 4 frame names"):
        quadruped_gait("solo12", feet=FEET[:3])
    with pytest.raises(InputError, match="no frame 'paw'"):
        quadruped_gait("solo12", feet=("paw", *FEET[1:]))
    with pytest.raises(InputError, match="'gallop' is not one of"):
        quadruped_gait("solo12", gait="gallop")
    with pytest.raises(InputError, match="no floating base"):
        quadruped_gait("iiwa", feet=("iiwa_link_1",) * 4)
    with pytest.raises(InputError, match="step_knots"):
        quadruped_gait("solo12", step_knots=1)
    with pytest.raises(InputError, match="limits: expected names among"):
        quadruped_gait("solo12", limits=("speed",))
    with pytest.raises(InputError, match="limits: expected names among"):
        quadruped_gait("solo12", limits="velocity")


def test_joint_limits_are_hard_constraints_on_request() -> None:
    """ANYmal (its feet LF_FOOT, ...; standing on the ground): no limits by default, the
    URDF's velocity and torque limits when asked for."""
    feet = ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT")
    plain = quadruped_gait("anymal", feet, "jump", step_knots=4, support_knots=2)
    assert not [c.name for c in plain.constraints if c.name.startswith("limits_")]
    ocp = quadruped_gait("anymal", feet, "jump", step_knots=4, support_knots=2,
                         limits=("velocity", "torque", "velocity"))  # fmt: skip
    limited = {c.name: c.residual for c in ocp.constraints if c.name.startswith("limits_")}
    assert set(limited) == {"limits_velocity", "limits_torque"}
    assert np.allclose(limited["limits_velocity"].upper[6:], 15.0)  # ANYmal's URDF
    assert all(abs(c.position[2]) < 1e-5 for c in ocp.contacts)  # the feet on the ground


def test_velocity_limits_are_kept_at_the_knot_velocities_a_plan_reports() -> None:
    """The LGVI bounds the secant velocities; a knot's excess (the reported velocity, midway
    through its impulse, over the limit) tightens the two secant bounds around it by 1.5 times
    the excess, no other; ANYmal's jump (case 7 of its family), whose landing exceeds the limit
    after the first solve, is solved again and every reported velocity is within 15 rad/s."""
    ocp = gait_case("anymal-jump", 7)
    nlp, _ = maximal.build(ocp, jit=False)
    v = np.zeros((ocp.N + 1, ocp.robot.nv))
    v[5, 8] = -16.0  # 1 rad/s over the limit
    assert tighten_velocity_limits(nlp, v) == pytest.approx(1.0)
    (term,) = [t for t in nlp.problem.terms if t.name == "limits_velocity"]
    flat = term.bind["Rc"][1]
    knot, body = flat // nlp.mm.nb, flat % nlp.mm.nb
    vmax = np.arccos(term.parameters["cos_step"]) / ocp.dt
    cut = (np.isin(knot, (4, 5))) & (nlp.mm.idx_v[body] == 8)
    assert cut.sum() == 2
    np.testing.assert_allclose(vmax[cut], 15.0 - 1.5 - SLACK)
    np.testing.assert_allclose(vmax[~cut], 15.0)
    assert tighten_velocity_limits(nlp, np.zeros_like(v)) == 0.0

    plan = mb.plan(ocp, "ripm", warm_start="linear")
    assert plan.success and plan.extra["solves"] >= 2, plan.message
    assert np.abs(plan.v[:, 6:]).max() <= 15.0 + 1e-4
    check = mb.verify(plan)
    assert check.passed, check.reasons


def test_the_locomotion_benchmark_draws_reproducible_steps_and_parses_its_options() -> None:
    from mbplan.cli.main import build_parser
    from mbplan.tasks.locomotion import FAMILIES, HEIGHT_RANGE, LENGTH_RANGE

    trot = "solo12-trot"
    nominal, drawn, again = gait_case(trot, 0), gait_case(trot, 3, 1), gait_case(trot, 3, 1)
    assert nominal.to_dict() != drawn.to_dict() and drawn.to_dict() == again.to_dict()
    stances = [c for c in drawn.contacts if c.frame == "FL_FOOT"]  # one step of full length
    step = stances[-1].position[0] - stances[0].position[0]
    length, height = FAMILIES[trot].length, FAMILIES[trot].height
    assert len(stances) == 2 and LENGTH_RANGE[0] <= step / length <= LENGTH_RANGE[1]
    swing = max(drawn[n].residual.translation[2] for n in drawn.names if n.startswith("swing"))
    assert HEIGHT_RANGE[0] <= (swing - drawn.contacts[0].position[2]) / height <= HEIGHT_RANGE[1]
    walk = gait_case("talos_legs-walk", 1)
    assert all(c.dim == 6 for c in walk.contacts)
    jump = gait_case("anymal-jump", 0)
    assert "limits_velocity" in jump.names
    with pytest.raises(InputError, match="unknown gait family 'solo12-gallop'"):
        gait_case("solo12-gallop", 0)
    args = build_parser().parse_args(
        ["bench", "locomotion", "--gaits", "solo12-trot,talos_legs-walk", "--n", "2"]
    )
    assert args.gaits == ("solo12-trot", "talos_legs-walk") and args.n == 2


def test_crocoddyl_s_own_gait_is_the_timing_anchor() -> None:
    """The benchmark's anchor: Crocoddyl's FDDP converges on its own trot of the same size
    (2 supports and 2 steps of 8 intervals, plus its 2 impulse models), and the section says
    so; without the baselines extra it says why it did not run."""
    pytest.importorskip("crocoddyl")
    from mbplan.baselines.crocoddyl_gaits import fddp_gait
    from mbplan.benchmarks.locomotion import anchor_markdown

    r = fddp_gait("solo12", FEET, "trot", 0.1, 0.05, 0.02, 8, 2, repeats=1)
    assert r["converged"] and r["knots"] == 22 and r["solve_time_s"] > 0.0
    assert r["max_cone_violation"] >= 0.0
    assert "| trot | 22 |" in "\n".join(anchor_markdown({"trot": r}))
    assert anchor_markdown({"unavailable": "no crocoddyl"})[-1] == "Not run: no crocoddyl"


@pytest.mark.parametrize("gait", ["walk", "jump"])
def test_the_biped_schedules_are_crocoddyl_s_phase_by_phase(gait: str) -> None:
    """As for the quadrupeds: Crocoddyl's running models but its impulse models, then one
    support interval more; the soles are 6-D contacts of Crocoddyl's sole size."""
    pytest.importorskip("crocoddyl")
    from crocoddyl.utils.biped import SimpleBipedGaitProblem

    robot = mb.load_robot("talos_legs")
    soles = ("left_sole_link", "right_sole_link")
    q0 = robot.configuration("half_sitting")
    x0 = np.concatenate([q0, np.zeros(robot.nv)])
    builder = SimpleBipedGaitProblem(robot.model, soles[1], soles[0])
    if gait == "jump":
        problem = builder.createJumpingProblem(x0, 0.1, np.array([0.2, 0.0, 0.0]), 0.03, 4, 5)
    else:
        problem = builder.createWalkingProblem(x0, 0.3, 0.1, 0.03, 5, 4)
    expected = [
        sorted(name.removesuffix("_contact") for name in m.differential.contacts.active_set)
        for m in problem.runningModels
        if hasattr(m, "differential")
    ]
    ocp = biped_gait(robot, soles, gait, step_knots=5, support_knots=4)
    assert _contact_sets(ocp) == [*expected, sorted(soles)]
    assert all(c.sole == (0.1, 0.05) and c.dim == 6 for c in ocp.contacts)


def test_biped_gait_inputs_are_refused_by_name() -> None:
    with pytest.raises(InputError, match="expected 2 frame names"):
        biped_gait("talos_legs", feet=("left_sole_link",))
    with pytest.raises(InputError, match="'trot' is not one of walk, jump"):
        biped_gait("talos_legs", gait="trot")
    with pytest.raises(InputError, match=r"sole .* must be positive"):
        biped_gait("talos_legs", sole=(0.2, 0.0))
