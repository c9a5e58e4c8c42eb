"""Quadruped and biped gaits as OCPs: the schedules and targets of Crocoddyl's
``SimpleQuadrupedalGaitProblem`` and ``SimpleBipedGaitProblem`` (``crocoddyl.utils.quadruped``,
``.biped``), with hard contacts and friction cones: point feet for quadrupeds, flat soles
(6-D contacts, their wrenches in the contact wrench cone) for bipeds.

A gait is a list of :class:`Phase` (intervals, feet that swing): Crocoddyl's running models
without its impulse models (a touchdown is the force of the contact's first knot,
:mod:`mbplan.ocp.contacts`), and one more support interval, so that the plan does not end on a
landing (the LGVI's touchdown impulse and the feet's rest at the end would share one interval). Knot ``t`` starts a phase; a support phase of ``S`` intervals keeps
every foot on the ground; a step phase of ``K`` intervals lifts its feet after knot ``t`` and puts
them down at knot ``t + K``, ``step_length`` further along ``x`` (the first step of a walk, trot
or pace is half as long). Every stance of a foot is one :meth:`~mbplan.OCP.add_contact` (its
position: where the foot starts, moved by its steps). Costs, Crocoddyl's targets at the knots of
its running models: at knot ``t + k`` of a step the centre of mass
(:class:`~mbplan.residuals.ComPosition`, starting over the feet's centre) is ``(k+1)/K`` of the
way to its next position (the step times the fraction of the feet that swing), a swing foot
(:class:`~mbplan.residuals.FrameTranslation`; from ``k = 1``, the foot is held at knot ``t``)
``(k+1)/K`` of its step ahead at a triangular height profile up to ``step_height``; the joints
stay near the start's posture and the torques small; a swing foot stays above the ground
(:class:`~mbplan.residuals.FrameHeight`, hard); joint limits only on request (:data:`LIMITS`).
A jump takes off after ``S`` support intervals,
flies ``K`` intervals up (its centre of mass rising to ``step_height`` above the halfway point)
and ``K`` down, and lands ``step_length`` further on for ``S`` intervals (a biped's ``S/2``, as
Crocoddyl's) with its centre of mass there. A biped walks with a support phase before each
step, the right foot first (half a step), then the left; its swing soles track the placement
(:class:`~mbplan.residuals.FramePlacement`: the start's orientation) and land flat.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.ocp.contacts import frame_position, frame_rotation
from mbplan.ocp.problem import OCP
from mbplan.residuals import (
    ComPosition,
    FrameHeight,
    FramePlacement,
    FrameTranslation,
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocity,
    JointVelocityLimits,
)
from mbplan.robots.robot import load_robot
from mbplan.validation import as_array, as_int, as_real

QUADRUPED_GAITS: dict[str, tuple[tuple[int, ...], ...]] = {
    "walk": ((3,), (1,), (2,), (0,)),  # rh, rf, then lh, lf
    "trot": ((1, 2), (0, 3)),  # rf + lh, then lf + rh
    "pace": ((1, 3), (0, 2)),  # the right feet, then the left
    "bound": ((0, 1), (2, 3)),  # the front feet, then the hind
    "jump": ((0, 1, 2, 3),),
}
"""The feet (indices into ``(lf, rf, lh, rh)``) that each step of a gait swings; a walk's
support phases come before its first and third steps."""

BIPED_GAITS: dict[str, tuple[tuple[int, ...], ...]] = {
    "walk": ((1,), (0,)),  # the right foot, then the left
    "jump": ((0, 1),),
}
"""The feet (indices into ``(left, right)``) that each step of a biped gait swings; support
phases come before each step."""

FOOT_WEIGHT = 1e4  # swing-foot tracking (Crocoddyl: 1e6 on the same error)
COM_WEIGHT = 1e4  # centre-of-mass tracking (Crocoddyl: 1e6)
POSTURE_WEIGHT = 1.0  # joint positions near the start's (Crocoddyl's state regularisation)
VELOCITY_WEIGHT = 1e-2
TORQUE_WEIGHT = 1e-3  # (Crocoddyl's control regularisation: 1e-1 on the same torques)
LIMITS = {
    "position": JointPositionLimits,
    "velocity": JointVelocityLimits,
    "torque": JointTorqueLimits,
}
"""The robot's joint limits a gait adds as hard constraints on request (``limits``), by name.
Crocoddyl's examples have none; without them a leg may whirl over its hip in flight (ANYmal's
jump, 0.3 m long and 0.15 m high: a hind knee at 63 rad/s in the RIPM's plan, which does not
verify; with ``("velocity",)``, its URDF's 15 rad/s, it does)."""


@dataclass(frozen=True)
class Phase:
    """``intervals`` long; the feet ``swing`` (indices) are in the air (none: support)."""

    intervals: int
    swing: tuple[int, ...] = ()


def quadruped_schedule(gait: str, step_knots: int, support_knots: int) -> list[Phase]:
    """The phases of a gait (module docstring)."""
    if gait not in QUADRUPED_GAITS:
        raise InputError(f"gait: {gait!r} is not one of {', '.join(QUADRUPED_GAITS)}")
    steps = QUADRUPED_GAITS[gait]
    support = Phase(support_knots)
    if gait == "jump":
        return [support, Phase(2 * step_knots, steps[0]), support]
    out = []
    for i, feet in enumerate(steps):
        if gait != "walk" or i % 2 == 0:
            out.append(support)
        out.append(Phase(step_knots, feet))
    return [*out, Phase(1)]


def biped_schedule(gait: str, step_knots: int, support_knots: int) -> list[Phase]:
    """The phases of a biped gait (module docstring)."""
    if gait not in BIPED_GAITS:
        raise InputError(f"gait: {gait!r} is not one of {', '.join(BIPED_GAITS)}")
    support = Phase(support_knots)
    if gait == "jump":
        landed = Phase(max(support_knots // 2, 1))
        return [support, Phase(2 * step_knots, BIPED_GAITS[gait][0]), landed]
    right, left = BIPED_GAITS[gait]
    return [support, Phase(step_knots, right), support, Phase(step_knots, left), Phase(1)]


def _feet(robot: Any, feet: Any, names: str) -> tuple[str, ...]:
    count = len(names.split(", "))
    if isinstance(feet, str) or len(tuple(feet)) != count:
        raise InputError(f"feet: expected {count} frame names ({names}), got {feet!r}")
    for f in feet:
        if not isinstance(f, str) or not robot.model.existFrame(f):
            raise InputError(f"feet: the robot has no frame {f!r}")
    return tuple(feet)


def quadruped_gait(
    robot: Any,
    feet: tuple[str, str, str, str] = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"),
    gait: str = "walk",
    step_length: float = 0.15,
    step_height: float = 0.1,
    dt: float = 0.01,
    step_knots: int = 25,
    support_knots: int = 2,
    friction: float = 0.7,
    start: np.ndarray | None = None,
    limits: tuple[str, ...] = (),
) -> OCP:
    """The OCP of a quadruped gait (module docstring) from ``start`` (default: the robot's
    ``standing`` configuration), point feet ``(lf, rf, lh, rh)`` on the ground; ``limits``:
    names of :data:`LIMITS`, the robot's joint limits of those kinds as hard constraints
    (``limits_<kind>``)."""
    robot = load_robot(robot)
    feet = _feet(robot, feet, "lf, rf, lh, rh")
    K, S = _knots(step_knots, support_knots)
    phases = quadruped_schedule(gait, K, S)
    return _gait_ocp(robot, feet, gait, phases, step_length, step_height, dt, friction, start,
                     "standing", None, limits)  # fmt: skip


def biped_gait(
    robot: Any,
    feet: tuple[str, str] = ("left_sole_link", "right_sole_link"),
    gait: str = "walk",
    step_length: float = 0.6,
    step_height: float = 0.1,
    dt: float = 0.03,
    step_knots: int = 15,
    support_knots: int = 4,
    friction: float = 0.7,
    start: np.ndarray | None = None,
    sole: tuple[float, float] = (0.1, 0.05),
    limits: tuple[str, ...] = (),
) -> OCP:
    """The OCP of a biped gait (module docstring; Crocoddyl's ``SimpleBipedGaitProblem``) from
    ``start`` (default: the robot's ``half_sitting`` configuration), flat soles of ``sole =
    (length, width)`` (:meth:`~mbplan.OCP.add_contact`; Crocoddyl's wrench cone's 0.1 m ×
    0.05 m) at ``feet = (left, right)``;
    ``limits`` as for :func:`quadruped_gait`."""
    robot = load_robot(robot)
    feet = _feet(robot, feet, "left, right")
    K, S = _knots(step_knots, support_knots)
    phases = biped_schedule(gait, K, S)
    return _gait_ocp(robot, feet, gait, phases, step_length, step_height, dt, friction, start,
                     "half_sitting", sole, limits)  # fmt: skip


def _knots(step_knots: int, support_knots: int) -> tuple[int, int]:
    K = as_int(step_knots, "step_knots", minimum=2, what="intervals of a step")
    S = as_int(support_knots, "support_knots", minimum=1, what="intervals of a support phase")
    return K, S


def _gait_ocp(
    robot: Any,
    feet: tuple[str, ...],
    gait: str,
    phases: list[Phase],
    step_length: float,
    step_height: float,
    dt: float,
    friction: float,
    start: np.ndarray | None,
    standing: str,
    sole: tuple[float, float] | None,
    limits: tuple[str, ...],
) -> OCP:
    """The OCP of the schedule ``phases`` of ``feet`` (module docstring)."""
    if not getattr(robot, "floating", False):
        raise InputError(f"{gait}: robot {robot.name!r} has no floating base")
    if isinstance(limits, str) or any(k not in LIMITS for k in limits):
        raise InputError(f"limits: expected names among {', '.join(LIMITS)}, got {limits!r}")
    length = as_real(step_length, "step_length")
    height = as_real(step_height, "step_height", positive=True)
    q0 = as_array(robot.configuration(standing) if start is None else start, (robot.nq,), "start")
    N = sum(p.intervals for p in phases)
    ocp = OCP(robot, N=N, dt=as_real(dt, "dt", positive=True), q0=q0)
    model = robot.model
    ids = [robot.frame_id(f) for f in feet]
    at = np.array([frame_position(model, i, q0) for i in ids])
    turn = [frame_rotation(model, i, q0) for i in ids]
    ground = at[:, 2].copy()
    data = model.createData()
    com = pin.centerOfMass(model, data, q0).copy()
    com[:2] = at[:, :2].mean(axis=0)
    stance_start = [0] * len(feet)
    first_step = gait in ("walk", "trot", "pace")

    def contact(i: int, knots: range) -> None:
        name = f"{feet[i]}_{stance_start[i]}"
        ocp.add_contact(name, feet[i], knots, at[i], friction, sole)

    def swing_target(i: int, target: np.ndarray) -> Any:
        if sole is None:
            return FrameTranslation(feet[i], target)
        return FramePlacement(feet[i], pin.SE3(turn[i], target))

    t = 0
    for p, phase in enumerate(phases):
        if not phase.swing:
            t += phase.intervals
            continue
        stride = 0.5 * length if first_step and p < (3 if gait == "walk" else 2) else length
        share = len(phase.swing) / len(feet)
        for i in phase.swing:  # the stance that ends here
            contact(i, range(stance_start[i], t + 1))
        flight = np.arange(t + 1, t + phase.intervals)
        for i in phase.swing:
            above = FrameHeight(feet[i], ground[i])
            ocp.add_constraint(f"above_{feet[i]}_{t}", above, knots=flight)
        K = phase.intervals // 2 if gait == "jump" else phase.intervals
        for k in range(K):
            ahead = (k + 1) / K  # Crocoddyl's targets for the state at knot t + k
            if gait == "jump":  # rising to step_height above the halfway point
                goal = com + np.array([0.5 * stride, 0.0, height]) * ahead
            else:
                goal = com + np.array([stride * share * ahead, 0.0, 0.0])
            ocp.add_cost(f"com_{t + k}", ComPosition(goal), COM_WEIGHT, knots=[t + k])
            if gait == "jump" or k == 0:  # knot t: the foot is still held
                continue
            rise = height * min(k, K - k) / (K / 2)
            for i in phase.swing:
                target = swing_target(i, at[i] + np.array([stride * ahead, 0.0, rise]))
                ocp.add_cost(f"swing_{feet[i]}_{t + k}", target, FOOT_WEIGHT, knots=[t + k])
        t += phase.intervals
        com = com + np.array([stride * share, 0.0, 0.0])
        for i in phase.swing:
            at[i] = at[i] + np.array([stride, 0.0, 0.0])
            stance_start[i] = t
    for i in range(len(feet)):
        contact(i, range(stance_start[i], N + 1))
    if gait == "jump":
        ocp.add_cost("com_landed", ComPosition(com), COM_WEIGHT, knots=range(t, N + 1))
    joints = robot.q_of_v[robot.joint_indices(None)]
    ocp.add_cost("posture", JointPosition(q0[joints]), POSTURE_WEIGHT)
    ocp.add_cost("velocity", JointVelocity(), VELOCITY_WEIGHT)
    ocp.add_cost("torque", JointTorque(), TORQUE_WEIGHT)
    if gait != "jump":
        ocp.add_cost("com_end", ComPosition(com), COM_WEIGHT, knots="terminal")
    for kind in dict.fromkeys(limits):
        ocp.add_constraint(f"limits_{kind}", LIMITS[kind]())
    return ocp
