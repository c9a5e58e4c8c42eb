"""RIPM option variants on the same cases: iterations and solved & verified counts (issue #12).

Every solve goes through ``mbplan.plan`` and ``mbplan.verify`` (``plan_row``, the benchmarks'
row): drone docking without and with input limits (geodesic warm start, tol 1e-6, max 100
iterations, as ``mbplan bench drone-docking``), the iiwa obstacle with the com and the distance
constraint (via warm start, tol 1e-6, max 500 iterations, as ``mbplan bench iiwa-obstacle``),
the chain reach with 4, 8 and 16 links (linear warm start, tol 1e-6, max 500) and the arm sweep
of ``tests/test_sweep.py`` (42 tasks from rest, max 200 iterations). The (case, variant) jobs
are interleaved so that every variant sees the same load. ``default`` is ``RIPMOptions()`` of
the checkout; the other variants are overrides of the session-6 defaults (``session6``).

    python benchmarks/barrier_variants.py --drone 30 --iiwa 30 --variants default session6 \
        --out benchmarks/results/barrier
    python benchmarks/barrier_variants.py --tasks chain4 chain8 chain16 sweep \
        --variants default session6
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ripm_options_ab import SESSION6  # the defaults before session 7
from tqdm import tqdm

PROBING = {"mu_strategy": "adaptive", "mu_oracle": "probing"}
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "session6": SESSION6,
    "default-full": {"kkt_method": "full"},
    "corrector": SESSION6 | {"corrector": True},
    "probing": SESSION6 | PROBING,
    "probing-corrector": SESSION6 | PROBING | {"corrector": True},
    "probing-cap": SESSION6 | PROBING | {"mu_max_fact": 0.0},
    "probing-cap-corrector": SESSION6 | PROBING | {"mu_max_fact": 0.0, "corrector": True},
    "loqo": SESSION6 | {"mu_strategy": "adaptive", "mu_oracle": "loqo"},
}
"""Name → :class:`~mbplan.solvers.RIPMOptions` overrides."""

TASKS = ("drone", "drone-limits", "iiwa", "iiwa-distance", "chain4", "chain8", "chain16", "sweep")
FIXED_CASES = {"chain4": 1, "chain8": 1, "chain16": 1, "sweep": 42}
"""Tasks with a fixed number of cases (the sweep: 21 arms × joint and frame goal)."""


@functools.cache
def _drone_cases(n: int, limits: bool) -> list:
    from mbplan.tasks.drone import sample_docking_cases

    return sample_docking_cases(n, 0, with_input_limits=limits)


@functools.cache
def _iiwa_starts(n: int, constraint: str) -> Any:
    from mbplan.paper import iiwa_obstacle_starts

    return iiwa_obstacle_starts(n, 0, constraint)


_SOLVES = [0]


def _count_kkt_solves() -> None:
    """Count the solver's KKT solves in this process (the Newton, affine, corrector and SOC
    solves, each with its iterative refinement): outermost calls of ``KKTSystem.solve`` and
    ``ReducedKKTSystem.solve`` (whose reduced matrix and fallback solve with a KKTSystem)."""
    from mbplan.solvers.linear_solver import KKTSystem
    from mbplan.solvers.reduced_step import ReducedKKTSystem

    depth = [0]
    for cls in (KKTSystem, ReducedKKTSystem):
        if getattr(cls.solve, "counted", False):
            continue

        def counted(self, *args, _solve=cls.solve, **kwargs):
            _SOLVES[0] += depth[0] == 0
            depth[0] += 1
            try:
                return _solve(self, *args, **kwargs)
            finally:
                depth[0] -= 1

        counted.counted = True
        cls.solve = counted


def solve(task: str, index: int, n: int, variant: str) -> dict[str, Any]:
    """One (task, case, variant) solve, verified, as a JSON row."""
    from mbplan.benchmarks.arm_sweep import sweep_case
    from mbplan.paper import drone_docking, iiwa_obstacle

    from mbplan.benchmarks.common import plan_row
    from mbplan.tasks.speed import chain_task

    _count_kkt_solves()
    _SOLVES[0] = 0
    options = VARIANTS[variant]
    extra = {}
    if task.startswith("iiwa"):
        constraint = "distance" if task == "iiwa-distance" else "com"
        ocp = iiwa_obstacle(_iiwa_starts(n, constraint)[index], N=40, constraint=constraint)
        row, _, _ = plan_row(ocp, "ripm", warm_start="via", tol=1e-6, max_iter=500, options=options)
    elif task.startswith("chain"):
        ocp = chain_task(int(task[5:]))
        row, _, _ = plan_row(
            ocp, "ripm", warm_start="linear", tol=1e-6, max_iter=500, options=options
        )
    elif task == "sweep":
        name, kind, ocp, rest = sweep_case(index)
        row, _, _ = plan_row(ocp, "ripm", warm_start=rest, max_iter=200, options=options)
        extra = {"robot": name, "kind": kind}
    else:
        ocp = drone_docking(_drone_cases(n, task == "drone-limits")[index])
        row, _, _ = plan_row(
            ocp, "ripm", warm_start="linear", tol=1e-6, max_iter=100, options=options
        )
    row.pop("verification_reasons")
    row["kkt_solves"] = _SOLVES[0]
    return {"task": task, "case": index, "variant": variant, **extra, **row}


def _solve(job: tuple) -> dict[str, Any]:
    return solve(*job)


def summarize(rows: list[dict[str, Any]], variants: list[str]) -> str:
    """Markdown table: per task and variant median / mean / max iterations, converged, solved &
    verified, KKT solves per iteration, median solve time and time per iteration (ratios to the
    first variant)."""
    lines = [
        "| task | variant | cases | iterations median / mean / max | converged | solved & verified "
        "| KKT solves per iteration | median solve time (s) | ratio | median time per iteration "
        "(ms) | ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for task in TASKS:
        base = base_it = None
        for v in variants:
            sel = [r for r in rows if r["task"] == task and r["variant"] == v]
            if not sel:
                continue
            it = [r["iterations"] for r in sel]
            t = statistics.median(r["solve_time_s"] for r in sel)
            t_it = statistics.median(r["time_per_iter_s"] for r in sel)
            if v == variants[0]:
                base, base_it = t, t_it
            solves = sum(r.get("kkt_solves", 0) for r in sel) / max(1, sum(it))
            conv = sum(r["status"] in ("converged", "CONVERGED") for r in sel)
            ok = sum(r["success"] and r["verified"] for r in sel)
            ratio = f"{t / base:.2f}" if base else "—"
            ratio_it = f"{t_it / base_it:.2f}" if base_it else "—"
            lines.append(
                f"| {task} | {v} | {len(sel)} | {statistics.median(it):g} / "
                f"{statistics.mean(it):.1f} / {max(it)} | {conv} | {ok} | {solves:.2f} | {t:.3f} "
                f"| {ratio} | {1e3 * t_it:.2f} | {ratio_it} |"
            )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drone", type=int, default=30, help="drone cases (of 100, seed 0)")
    ap.add_argument("--iiwa", type=int, default=30, help="iiwa com cases (of 100, seed 0)")
    ap.add_argument("--distance", type=int, default=30, help="iiwa distance cases (of 100)")
    ap.add_argument("--first", type=int, default=0, help="first case index")
    ap.add_argument("--cases", type=int, nargs="*", default=None, help="these case indices")
    ap.add_argument("--tasks", nargs="*", default=list(TASKS), choices=TASKS)
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--workers", type=int, default=2, choices=(1, 2))
    ap.add_argument("--out", default=None, help="folder for rows.json and results.md")
    args = ap.parse_args()
    jobs = []
    counts = {"iiwa": args.iiwa, "iiwa-distance": args.distance} | FIXED_CASES
    for task in args.tasks:
        count = counts.get(task, args.drone)
        for i in args.cases or range(args.first, args.first + count):
            jobs += [(task, i, 100, v) for v in args.variants]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_solve, jobs), total=len(jobs)))
    table = summarize(rows, args.variants)
    print(table)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "rows.json").write_text(json.dumps(rows, indent=1))
        command = "python benchmarks/barrier_variants.py " + " ".join(sys.argv[1:])
        (out / "results.md").write_text(f"`{command}`\n\n{table}\n")


if __name__ == "__main__":
    main()
