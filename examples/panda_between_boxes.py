"""The panda (fingers locked) from its default configuration to a hand pose between two boxes, in
both formulations; verified and saved. The same script as in README's Python API section.

    python examples/panda_between_boxes.py --out out
Exits with status 1 unless both plans are solved, verified and reach the pose within 1 mm and
1e-3 rad.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import mbplan as mb

GOAL = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([0.5, 0.0, 0.25]))


def task() -> mb.OCP:
    """The panda (fingers locked), from its SRDF default configuration at rest, to ``GOAL``."""
    robot = mb.load_robot("panda", lock=["panda_finger_joint1", "panda_finger_joint2"])
    scene = mb.Scene().add_box("left", (0.3, 0.1, 0.4), (0.5, 0.2, 0.2))
    scene.add_box("right", (0.3, 0.1, 0.4), (0.5, -0.2, 0.2))
    ocp = mb.OCP(robot, scene, N=30, dt=0.05)
    ocp.add_cost("velocity", mb.residuals.JointVelocity(), 1e-2)
    ocp.add_cost("effort", mb.residuals.JointTorque(), 1e-4)
    ocp.add_terminal_constraint("hand", mb.residuals.FramePlacement("panda_hand", GOAL))
    ocp.add_constraint("clearance", mb.residuals.Distance(margin=0.01))
    ocp.add_constraint("limits", mb.residuals.JointPositionLimits())
    ocp.add_constraint("torque", mb.residuals.JointTorqueLimits())
    return ocp


def main(out: Path) -> int:
    ocp = task()
    robot, goal = ocp.robot, GOAL
    ok = True
    for method in ("ripm", "ipopt"):
        plan = mb.plan(ocp, method, warm_start="via")
        check = mb.verify(plan)
        model, data = robot.model, robot.model.createData()
        pin.framesForwardKinematics(model, data, plan.q[-1])
        M = data.oMf[model.getFrameId("panda_hand")]
        dp = float(np.linalg.norm(M.translation - goal.translation))
        dR = float(np.linalg.norm(pin.log3(goal.rotation.T @ M.rotation)))
        print(
            f"{method} ({plan.formulation}): {plan.status}, {plan.iterations} iterations, "
            f"success {plan.success}, verified {check.passed}; hand error {1e3 * dp:.2g} mm, "
            f"{dR:.2g} rad" + "".join(f"\n  - {r}" for r in check.reasons)
        )
        print(f"saved {mb.save_npz(plan, out / f'panda_{method}.npz')}")
        ok &= plan.success and check.passed and dp <= 1e-3 and dR <= 1e-3
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out", help="output folder")
    sys.exit(main(Path(parser.parse_args().out)))
