"""The delta robot (three legs closed on a translating platform) carries its platform between two
points over a box, in both formulations; verified, saved and replayed (an offline meshcat page).

    python examples/delta_obstacle.py --out out/delta
The robot is the bundled ``delta`` (``mbplan robots``): three point closures, the three
shoulders actuated, the platform's virtual prismatic joints and the universal elbow joints
passive, 3 degrees of freedom. The start closes the loops with the platform held at ``DELTA_START``
(:func:`mbplan.tasks.mechanisms.delta_configuration`); coal distances of the legs' and the platform's
collision geometry to the box stay above 1 cm. The same task as
``examples/tasks/delta_obstacle.toml``. Exits with status 1 unless every plan is solved,
verified, brings the platform within 1 mm of ``DELTA_GOAL`` at rest and keeps the loops closed.
The task is :func:`mbplan.tasks.mechanisms.delta_obstacle` (case 0 of ``mbplan bench loops``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import mbplan as mb
from mbplan.robots.loops import closure_residual
from mbplan.tasks.mechanisms import DELTA_GOAL, TOL, WARM_START, delta_obstacle
from mbplan.viz import static_html


def main(out: Path, methods: list[str], N: int) -> int:
    ocp = delta_obstacle(N=N)
    robot = ocp.robot
    model, data = robot.model, robot.model.createData()
    frame = model.getFrameId("platform")
    ok, plans = True, []
    for method in methods:
        plan = mb.plan(ocp, method, warm_start=WARM_START, tol=TOL)
        check = mb.verify(plan)
        pin.framesForwardKinematics(model, data, plan.q[-1])
        error = float(np.linalg.norm(data.oMf[frame].translation - DELTA_GOAL))
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
