"""The drone docking cases through the OCP API and through the task's own transcriptions, side
by side in one run: per-case convergence, iteration counts and time per iteration (ratio, same run) of the RIPM (with and without input
limits) and of the quaternion IPOPT.

Regenerate: ``python benchmarks/drone_docking_side_by_side.py`` (from the repository root)
→ ``benchmarks/results/drone-docking-ocp/side-by-side.{json,md}``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from tqdm import tqdm

import mbplan
from mbplan import paper
from mbplan.baselines import solve_quaternion_ipopt
from mbplan.planning.drone import plan_docking
from mbplan.solvers import RIPMOptions
from mbplan.tasks.drone import sample_docking_cases

OUT = Path("benchmarks/results/drone-docking-ocp")
N_CASES, SEED, TOL = 100, 0, 1e-6


def main() -> None:
    rows = {}
    for method, limits in (("ripm", False), ("ripm-input-limits", True), ("ipopt", False)):
        direct, api = [], []
        for task in tqdm(sample_docking_cases(N_CASES, SEED, with_input_limits=limits), method):
            if method == "ipopt":
                d = solve_quaternion_ipopt(task, max_iter=1000, tol=TOL)
                direct.append((bool(d.success), int(d.iterations), d.time_per_iteration))
            else:
                d = plan_docking(task, RIPMOptions(tol=TOL, max_iter=100))
                per_iter = d.result.wall_time_s / max(d.result.iterations, 1)
                direct.append((d.converged, int(d.result.iterations), per_iter))
            max_iter = 1000 if method == "ipopt" else 100
            ocp = paper.drone_docking(task)
            r = mbplan.plan(
                ocp,
                method.removesuffix("-input-limits"),
                warm_start="linear",
                tol=TOL,
                max_iter=max_iter,
            )
            ok = bool(r.success and mbplan.verify(r).passed)
            api.append((ok, int(r.iterations), r.time_per_iter_s))
        differ = [
            (k, d[1], a[1])
            for k, (d, a) in enumerate(zip(direct, api, strict=True))
            if d[1] != a[1]
        ]
        rows[method] = {
            "direct_converged": sum(d[0] for d in direct),
            "api_converged_and_verified": sum(a[0] for a in api),
            "direct_median_iters": float(np.median([d[1] for d in direct])),
            "api_median_iters": float(np.median([a[1] for a in api])),
            "cases_with_different_iterations": differ,
            "median_time_per_iter_ratio_api_over_direct": float(
                np.median([a[2] / d[2] for d, a in zip(direct, api, strict=True)])
            ),
        }
    (OUT / "side-by-side.json").write_text(json.dumps(rows, indent=1) + "\n")
    lines = [
        "# Drone docking: OCP API vs the task's own transcriptions (same run)",
        "",
        "Command: `python benchmarks/drone_docking_side_by_side.py`"
        f" ({N_CASES} cases, seed {SEED}, tol {TOL:g})",
        "",
        "| method | direct converged | API converged & verified | direct median iters "
        "| API median iters | cases with other iteration counts | time/iter API/direct (median) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for m, r in rows.items():
        lines.append(
            f"| {m} | {r['direct_converged']}/{N_CASES} | {r['api_converged_and_verified']}/"
            f"{N_CASES} | {r['direct_median_iters']:g} | {r['api_median_iters']:g} | "
            f"{len(r['cases_with_different_iterations'])} | "
            f"{r['median_time_per_iter_ratio_api_over_direct']:.2f} |"
        )
    (OUT / "side-by-side.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
