"""Floating-base robots in free flight (``mbplan bench floating``): released at rest 1 m above
the ground (contacts are not modelled), the robot turns every joint by a random angle of at
most :data:`SWING` from its standing posture (within the central half of the joint's range) in
:data:`DURATION`, a hard terminal constraint, with the least torque, within its position,
velocity and torque limits. Case ``i`` of a robot draws from
``numpy.random.default_rng((seed, i, ROBOT_TAG[robot]))``, so a case does not depend on how
many are drawn."""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.ocp.problem import OCP
from mbplan.residuals import (
    JointPosition,
    JointPositionLimits,
    JointTorque,
    JointTorqueLimits,
    JointVelocityLimits,
)
from mbplan.robots.robot import load_robot

FLOATING_ROBOTS = ("solo12", "anymal", "go2", "talos_legs")
ROBOT_TAG = {name: i for i, name in enumerate(FLOATING_ROBOTS)}
N, DT = 20, 0.02
DURATION = N * DT  # s
HEIGHT = 1.0  # m, the base at release
SWING = 0.8  # rad, the largest change of a joint's angle
RANGE_FRACTION = 0.5  # targets within this central fraction of each joint's range
EFFORT_WEIGHT = 1e-3
WARM_START = "linear"


def free_flight_case(robot: str, index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``robot`` (module docstring)."""
    if robot not in ROBOT_TAG:
        raise InputError(f"unknown robot {robot!r}; choose from {', '.join(FLOATING_ROBOTS)}")
    model = load_robot(robot)
    rng = np.random.default_rng((seed, index, ROBOT_TAG[robot]))
    q0 = model.configuration("default")
    q0[2] = HEIGHT
    joints = model.joint_indices(None)
    iq = model.q_of_v[joints]
    lo, hi = model.model.lowerPositionLimit[iq], model.model.upperPositionLimit[iq]
    mid, half = 0.5 * (lo + hi), 0.5 * RANGE_FRACTION * (hi - lo)
    target = np.clip(q0[iq] + rng.uniform(-SWING, SWING, len(joints)), mid - half, mid + half)
    ocp = OCP(model, N=N, dt=DT, q0=q0)
    ocp.add_constraint("goal", JointPosition(target=target), knots="terminal")
    ocp.add_cost("effort", JointTorque(), weight=EFFORT_WEIGHT)
    ocp.add_constraint("position_limits", JointPositionLimits())
    ocp.add_constraint("velocity_limits", JointVelocityLimits())
    ocp.add_constraint("torque_limits", JointTorqueLimits())
    return ocp
