"""The delta robot (three legs closed on a translating platform) carries its platform between two
points over a box, in both formulations; verified, saved and replayed (an offline meshcat page).

    python examples/delta_obstacle.py --out out/delta
The robot is the bundled ``delta`` (``mbplan robots``): three point closures, the three
shoulders actuated, the platform's virtual prismatic joints and the universal elbow joints
passive, 3 degrees of freedom. The start closes the loops with the platform held at ``START``
(:func:`mbplan.robots.loops.close_loops`); coal distances of the legs' and the platform's
collision geometry to the box stay above 1 cm. The same task as
``examples/tasks/delta_obstacle.toml``. Exits with status 1 unless every plan is solved,
verified, brings the platform within 1 mm of ``GOAL`` at rest and keeps the loops closed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import mbplan as mb
from mbplan.robots.loops import close_loops, closure_residual
from mbplan.viz import static_html

START = np.array([-0.15, 0.0, 0.40])  # platform centre (m)
GOAL = np.array([0.15, 0.0, 0.40])
PLATFORM_AT_NEUTRAL = np.array([0.0, 0.0, 0.427996])  # where qpos0 puts it


def start_configuration(robot: mb.Robot, platform: np.ndarray) -> np.ndarray:
    """The closed configuration with the platform at ``platform`` (the legs follow)."""
    slides = robot.joint_indices(["platform_x", "platform_y", "platform_z"])
    q = np.zeros(robot.nq)
    q[slides] = platform - PLATFORM_AT_NEUTRAL
    q, gap = close_loops(robot.model, robot.loops, q, fixed=slides)
    if gap > 1e-9:
        raise SystemExit(f"the legs cannot reach the platform at {platform}: gap {gap:.3g} m")
    return q


def task(N: int = 40, dt: float = 0.05) -> mb.OCP:
    """From rest at ``START`` to ``GOAL`` at rest, over the box."""
    robot = mb.load_robot("delta")
    scene = mb.Scene().add_box("box", (0.08, 0.3, 0.12), (0.0, 0.0, 0.30))
    ocp = mb.OCP(robot, scene, N=N, dt=dt, q0=start_configuration(robot, START))
    ocp.add_cost("velocity", mb.residuals.JointVelocity(), 1e-2)
    ocp.add_cost("effort", mb.residuals.JointTorque(joints=list(actuated(robot))), 1e-3)
    ocp.add_terminal_constraint("platform", mb.residuals.FrameTranslation("platform", GOAL))
    ocp.add_terminal_constraint("rest", mb.residuals.JointVelocity())
    ocp.add_constraint("clearance", mb.residuals.Distance(margin=0.01))
    ocp.add_constraint("limits", mb.residuals.JointPositionLimits())
    ocp.add_constraint("torque", mb.residuals.JointTorqueLimits())
    return ocp


def actuated(robot: mb.Robot) -> tuple[str, ...]:
    return tuple(n for n in robot.model.names[1:] if n not in robot.passive)


def main(out: Path, methods: list[str], N: int) -> int:
    ocp = task(N=N)
    robot = ocp.robot
    model, data = robot.model, robot.model.createData()
    frame = model.getFrameId("platform")
    ok, plans = True, []
    for method in methods:
        plan = mb.plan(ocp, method, warm_start="via")
        check = mb.verify(plan)
        pin.framesForwardKinematics(model, data, plan.q[-1])
        error = float(np.linalg.norm(data.oMf[frame].translation - GOAL))
        gap = max(float(np.max(np.abs(closure_residual(model, robot.loops, q)))) for q in plan.q)
        heights = []
        for q in plan.q:
            pin.framesForwardKinematics(model, data, q)
            heights.append(data.oMf[frame].translation[2])
        print(
            f"{method} ({plan.formulation}): {plan.status}, {plan.iterations} iterations, "
            f"success {plan.success}, verified {check.passed}; platform error {1e3 * error:.2g} "
            f"mm, highest at z = {max(heights):.3f} m, loop gap {gap:.2g} m"
            + "".join(f"\n  - {r}" for r in check.reasons)
        )
        print(f"saved {mb.save_npz(plan, out / f'delta_{method}.npz')}")
        ok &= plan.success and check.passed and error <= 1e-3 and gap <= 1e-6
        plans.append(plan)
    print(f"wrote {static_html(plans, out / 'delta.html')}")
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/delta"), help="output folder")
    parser.add_argument("--methods", default="ripm,ipopt", help="comma-separated methods")
    parser.add_argument("--horizon", type=int, default=40, help="number of steps N")
    a = parser.parse_args()
    sys.exit(main(a.out, a.methods.split(","), a.horizon))
