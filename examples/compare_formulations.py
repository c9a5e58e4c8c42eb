"""Maximal (RIPM on SO(3)×R³ bodies) vs generalized (IPOPT on joint angles) coordinates on the
same iiwa task (an :class:`mbplan.OCP` of :mod:`mbplan.tasks.paper`), same warm start, both verified
by the same independent replay.

    python examples/compare_formulations.py --out out/compare
writes ``ripm.npz``, ``ipopt.npz``, ``side_by_side.html`` (meshcat, offline) and
``convergence.png``; ``--seed S`` picks a random start, ``--max-iter`` bounds both solvers.
Exits with status 1 unless both plans are solved and verified.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import mbplan as mb
from mbplan.tasks.paper import iiwa_obstacle, iiwa_obstacle_cases
from mbplan.viz import plot_convergence, static_html


def main(out: Path, seed: int | None, max_iter: int) -> int:
    ocp = iiwa_obstacle() if seed is None else iiwa_obstacle_cases(1, seed)[0]
    results, ok = [], True
    print(f"{'method':<22}{'status':<18}{'iters':>6}{'ms/iter':>9}{'total s':>9}  verified")
    for method in ("ripm", "ipopt"):
        r = mb.plan(ocp, method, warm_start="via", max_iter=max_iter)
        check = mb.verify(r)
        print(
            f"{r.method:<22}{r.status:<18}{r.iterations:>6}{1e3 * r.time_per_iter_s:>9.1f}"
            f"{r.total_time_s:>9.2f}  {check.passed}"
        )
        r.save(out / f"{method}.npz")
        results.append(r)
        ok &= r.success and check.passed
    print(f"wrote {static_html(results, out / 'side_by_side.html', frame=ocp.N)}")
    print(f"wrote {plot_convergence(results, out / 'convergence.png')}")
    return 0 if ok else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("out/compare"))
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--max-iter", type=int, default=500)
    a = parser.parse_args()
    raise SystemExit(main(a.out, a.seed, a.max_iter))
