"""Plan for another example-robot-data arm (UR5 by default) in both formulations.

    python examples/other_arm.py --robot ur5 --out out/ur5
A joint-space point-to-point :class:`mbplan.OCP` (:func:`mbplan.tasks.paper.tracking_ocp`) with an
obstacle out of the way. Any fixed-base arm whose joints are all revolute works in maximal
coordinates; prismatic joints (the panda's fingers) must be locked (``load_robot(..., lock=)``).
Exits with status 1 unless both plans are solved and verified.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import mbplan as mb
from mbplan.tasks.paper import add_obstacle_constraint, tracking_ocp


def main(robot: str, out: Path, N: int, max_iter: int) -> int:
    model = mb.load_robot(robot).model
    lo, hi = (
        np.maximum(model.lowerPositionLimit, -np.pi),
        np.minimum(model.upperPositionLimit, np.pi),
    )
    mid = 0.5 * (lo + hi)
    q0, q_target = mid + 0.15 * (hi - lo), mid - 0.15 * (hi - lo)
    scene = mb.Scene().add_cylinder("post", 0.05, 1.5, (2.0, 2.0, 0.75))
    ocp = add_obstacle_constraint(tracking_ocp(robot, q0, q_target, scene, N=N, dt=3.0 / N), "com")
    ok = True
    for method in ("ripm", "ipopt"):
        r = mb.plan(ocp, method, warm_start="linear", max_iter=max_iter)
        check = mb.verify(r)
        print(
            f"{r.method}: {r.status}, {r.iterations} iterations, {r.total_time_s:.2f} s, "
            f"verified: {check.passed}" + "".join(f"\n  - {x}" for x in check.reasons)
        )
        print(f"wrote {r.save(out / f'{robot}_{method}.npz')}")
        ok &= r.success and check.passed
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robot", default="ur5")
    parser.add_argument("--out", type=Path, default=Path("out/other_arm"))
    parser.add_argument("--horizon", type=int, default=40)
    parser.add_argument("--max-iter", type=int, default=500)
    a = parser.parse_args()
    raise SystemExit(main(a.robot, a.out, a.horizon, a.max_iter))
