"""The plans ``mbplan warmup`` makes once, so that the common paths' kernels (CasADi functions
compiled to C, numba functions) and per-task structures are compiled and cached on disk before
the first real plan: the README's iiwa task in maximal (RIPM) and generalized (IPOPT)
coordinates, the iiwa with coal distances, the README script's panda (a frame placement goal),
the drone docking (RIPM and MS-iLQR: the free body's formulations) and the speed benchmark's
8-link chain."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mbplan.ocp.problem import OCP


@dataclass(frozen=True)
class WarmupPlan:
    """``plan(ocp(), method, warm_start=warm_start)`` (:func:`mbplan.plan`)."""

    task: str
    method: str
    warm_start: str
    ocp: Callable[[], OCP]

    @property
    def name(self) -> str:
        return f"{self.task}-{self.method}"


def _iiwa() -> OCP:
    from mbplan.tasks.paper import iiwa_obstacle

    return iiwa_obstacle(N=40, constraint="com")  # `mbplan plan --robot iiwa`'s


def _iiwa_distance() -> OCP:
    from mbplan.tasks.speed import iiwa_task

    return iiwa_task(0, constraint="distance")  # the speed benchmark's first case


def _drone() -> OCP:
    from mbplan.tasks.speed import drone_task

    return drone_task(0)


def _panda() -> OCP:
    """The README's script: the panda's hand to a pose between two boxes (a terminal frame
    placement, coal distances of convex hulls)."""
    import numpy as np
    import pinocchio as pin

    from mbplan.ocp.scene import Scene
    from mbplan.residuals import Distance, FramePlacement, JointTorque, JointVelocity
    from mbplan.robots.robot import load_robot

    robot = load_robot("panda", lock=["panda_finger_joint1", "panda_finger_joint2"])
    scene = Scene().add_box("left", (0.3, 0.1, 0.4), (0.5, 0.2, 0.2))
    scene.add_box("right", (0.3, 0.1, 0.4), (0.5, -0.2, 0.2))
    goal = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([0.5, 0.0, 0.25]))
    ocp = OCP(robot, scene, N=30, dt=0.05).add_cost("velocity", JointVelocity(), 1e-2)
    ocp.add_cost("effort", JointTorque(), 1e-4)
    ocp.add_terminal_constraint("hand", FramePlacement("panda_hand", goal))
    return ocp.add_constraint("clearance", Distance(margin=0.01))


def _chain8() -> OCP:
    from mbplan.tasks.speed import chain_task

    return chain_task(8)


WARMUP_PLANS: tuple[WarmupPlan, ...] = (
    WarmupPlan("iiwa", "ripm", "via", _iiwa),
    WarmupPlan("iiwa", "ipopt", "via", _iiwa),
    WarmupPlan("iiwa-distance", "ripm", "via", _iiwa_distance),
    WarmupPlan("panda", "ripm", "via", _panda),
    WarmupPlan("drone", "ripm", "via", _drone),
    WarmupPlan("drone", "ms-ilqr", "via", _drone),
    WarmupPlan("chain8", "ripm", "linear", _chain8),
)
"""What ``mbplan warmup`` plans, in order (names: :attr:`WarmupPlan.name`)."""
