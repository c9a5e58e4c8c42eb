"""The crank-rocker four-bar (closed loop, crank actuated) driven from rest to a rocker angle, in
both formulations; verified, saved and replayed (an offline meshcat page).

    python examples/fourbar_crank.py --out out/fourbar
The robot is the bundled ``fourbar`` (``mbplan robots``): one point closure, the coupler and
rocker passive (zero torque at every interval), 1 degree of freedom. The same task as
``examples/tasks/fourbar_crank.toml``. Exits with status 1 unless every plan is solved,
verified, reaches the rocker angle within 1e-4 rad at rest and keeps the loop closed. The task
is :func:`mbplan.tasks.mechanisms.fourbar_crank` (case 0 of ``mbplan bench loops``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import mbplan as mb
from mbplan.robots.loops import closure_residual
from mbplan.tasks.mechanisms import ROCKER_GOAL, TOL, WARM_START, fourbar_crank
from mbplan.viz import static_html


def loop_gap(plan: mb.PlanResult) -> float:
    """The largest closure residual (m) of the plan's knots."""
    robot = plan.ocp.robot
    return max(float(np.max(np.abs(closure_residual(robot.model, robot.loops, q)))) for q in plan.q)


def main(out: Path, methods: list[str], N: int) -> int:
    ocp = fourbar_crank(N=N)
    rocker = int(ocp.robot.joint_indices(["rocker_joint"])[0])
    passive = ocp.robot.joint_indices(ocp.robot.passive)
    ok, plans = True, []
    for method in methods:
        plan = mb.plan(ocp, method, warm_start=WARM_START, tol=TOL)
        check = mb.verify(plan)
        error = abs(plan.q[-1, rocker] - ROCKER_GOAL)
        gap, rest = loop_gap(plan), float(np.max(np.abs(plan.v[-1])))
        print(
            f"{method} ({plan.formulation}): {plan.status}, {plan.iterations} iterations, "
            f"success {plan.success}, verified {check.passed}; rocker error {error:.2g} rad, "
            f"final speed {rest:.2g} rad/s, loop gap {gap:.2g} m, passive torque "
            f"{np.max(np.abs(plan.tau[:, passive])):.2g} N m, crank at {plan.q[-1, 0]:.3f} rad"
            + "".join(f"\n  - {r}" for r in check.reasons)
        )
        print(f"saved {mb.save_npz(plan, out / f'fourbar_{method}.npz')}")
        ok &= plan.success and check.passed and error <= 1e-4 and gap <= 1e-6
        plans.append(plan)
    print(f"wrote {static_html(plans, out / 'fourbar.html')}")
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/fourbar"), help="output folder")
    parser.add_argument("--methods", default="ripm,ipopt", help="comma-separated methods")
    parser.add_argument("--horizon", type=int, default=40, help="number of steps N")
    a = parser.parse_args()
    sys.exit(main(a.out, a.methods.split(","), a.horizon))
