"""Plan for another example-robot-data arm (UR5 by default) in both formulations.

    python examples/other_arm.py --robot ur5 --out out/ur5
Any fixed-base arm whose joints are all revolute works in maximal coordinates (the panda's finger
joints are prismatic: its generalized plan works, the maximal one raises a clear error).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mbplan.errors import MbplanError
from mbplan.planning.solve import plan
from mbplan.results import save_npz
from mbplan.tasks.obstacle import Cylinder, ObstacleTask
from mbplan.verification import verify


def main(robot: str, out: Path, N: int, max_iter: int) -> int:
    from mbplan.robots import load

    model = load(robot).model
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    mid = 0.5 * (np.maximum(lo, -np.pi) + np.minimum(hi, np.pi))
    q0 = mid + 0.15 * (np.minimum(hi, np.pi) - np.maximum(lo, -np.pi))
    q_target = mid - 0.15 * (np.minimum(hi, np.pi) - np.maximum(lo, -np.pi))
    task = ObstacleTask(
        robot=robot,
        N=N,
        dt=3.0 / N,
        q0=q0,
        q_target=q_target,
        obstacles=(Cylinder((2.0, 2.0), 0.05),),
    )
    for method in ("ripm", "ipopt"):
        try:
            r = plan(task, method, max_iter=max_iter)
        except MbplanError as exc:
            print(f"{method}: {exc}")
            continue
        check = verify(task, r)
        print(
            f"{r.method}: {r.status}, {r.iterations} iterations, {r.total_time_s:.2f} s, verified: {check.passed}"
        )
        print(f"wrote {save_npz(r, out / f'{robot}_{method}.npz')}")
    return 0


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
