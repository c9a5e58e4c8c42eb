"""Two 6-dof arms carry a bar together (the bar welded to both flanges: a closed loop) to a target
pose, in both formulations; verified, saved and replayed (an offline meshcat page).

    python examples/two_arm_carry.py --out out/two_arm_carry
The robot is the bundled ``two_arm_carry`` (``mbplan robots``): 12 actuated joints, one weld
closure, 6 degrees of freedom (the bar's pose); the closure forces make the arms share the
load. The same task as ``examples/tasks/two_arm_carry.toml``. Exits with status 1 unless every
plan is solved, verified, brings the bar's centre within 1 mm and 1e-3 rad of its goal
(:func:`mbplan.tasks.mechanisms.bar_goal`) at rest and keeps the loop closed. The task is
:func:`mbplan.tasks.mechanisms.two_arm_carry` (case 0 of ``mbplan bench loops``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import mbplan as mb
from mbplan.robots.loops import closure_residual
from mbplan.tasks.mechanisms import TOL, WARM_START, bar_goal, two_arm_carry
from mbplan.viz import static_html


def main(out: Path, methods: list[str], N: int) -> int:
    ocp = two_arm_carry(N=N)
    goal = bar_goal()
    robot = ocp.robot
    model, data = robot.model, robot.model.createData()
    ok, plans = True, []
    for method in methods:
        plan = mb.plan(ocp, method, warm_start=WARM_START, tol=TOL)
        check = mb.verify(plan)
        pin.framesForwardKinematics(model, data, plan.q[-1])
        M = data.oMf[model.getFrameId("bar_center")]
        dp = float(np.linalg.norm(M.translation - goal.translation))
        dR = float(np.linalg.norm(pin.log3(goal.rotation.T @ M.rotation)))
        gap = max(float(np.max(np.abs(closure_residual(model, robot.loops, q)))) for q in plan.q)
        half = model.nv // 2  # arm a's joints, then arm b's
        share = [float(np.abs(plan.tau[:, s]).max()) for s in (slice(0, half), slice(half, None))]
        print(
            f"{method} ({plan.formulation}): {plan.status}, {plan.iterations} iterations, "
            f"success {plan.success}, verified {check.passed}; bar error {1e3 * dp:.2g} mm, "
            f"{dR:.2g} rad, loop gap {gap:.2g}; largest torque arm a {share[0]:.3g} N m, "
            f"arm b {share[1]:.3g} N m" + "".join(f"\n  - {r}" for r in check.reasons)
        )
        print(f"saved {mb.save_npz(plan, out / f'two_arm_carry_{method}.npz')}")
        ok &= plan.success and check.passed and dp <= 1e-3 and dR <= 1e-3 and gap <= 1e-6
        plans.append(plan)
    print(f"wrote {static_html(plans, out / 'two_arm_carry.html')}")
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/two_arm_carry"), help="output folder")
    parser.add_argument("--methods", default="ripm,ipopt", help="comma-separated methods")
    parser.add_argument("--horizon", type=int, default=40, help="number of steps N")
    a = parser.parse_args()
    sys.exit(main(a.out, a.methods.split(","), a.horizon))
