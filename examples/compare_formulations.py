"""Maximal (RIPM on SO(3)×R³ bodies) vs generalized (IPOPT on joint angles) coordinates on the
same iiwa task, same warm start, both verified by the same independent replay.

    python examples/compare_formulations.py --out out/compare
writes ``ripm.npz``, ``ipopt.npz``, ``side_by_side.html`` (meshcat, offline) and
``convergence.png``; ``--seed S`` picks a random start, ``--max-iter`` bounds both solvers.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mbplan.planning.solve import plan
from mbplan.results import save_npz
from mbplan.tasks.obstacle import ObstacleTask, sample_obstacle_cases
from mbplan.verification import verify
from mbplan.viz import plot_convergence, static_html


def main(out: Path, seed: int | None, max_iter: int) -> int:
    task = ObstacleTask() if seed is None else sample_obstacle_cases("iiwa", 1, seed)[0]
    results = []
    print(f"{'method':<22}{'status':<18}{'iters':>6}{'ms/iter':>9}{'total s':>9}  verified")
    for method in ("ripm", "ipopt"):
        r = plan(task, method, max_iter=max_iter)
        check = verify(task, r)
        print(
            f"{r.method:<22}{r.status:<18}{r.iterations:>6}{1e3 * r.time_per_iter_s:>9.1f}"
            f"{r.total_time_s:>9.2f}  {check.passed}"
        )
        save_npz(r, out / f"{method}.npz")
        results.append(r)
    print(f"wrote {static_html(results, out / 'side_by_side.html', task, frame=task.N)}")
    print(f"wrote {plot_convergence(results, out / 'convergence.png')}")
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("out/compare"))
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--max-iter", type=int, default=500)
    a = parser.parse_args()
    raise SystemExit(main(a.out, a.seed, a.max_iter))
