"""The RIPM with ``kkt_method="reduced"`` (joints eliminated through the formulation's plan,
:mod:`mbplan.solvers.reduced_step`) against ``"full"``, interleaved in one run.

Part 1, one KKT per task (warm start, random multipliers ``y ~ N(0, 1)``, ``z, s`` in
``[0.5, 2]``, ``δ_w = 1e-6``): min over ``--repeats`` of ``set_matrices``, ``factorize`` and
``solve`` (10 refinement steps max, ratio 1e-10), full and reduced alternating.
Part 2, whole solves: every case solved with both methods alternating, ``--repeats`` times;
min total time per case, time per iteration, the KKT's share of it (outermost
``set_matrices`` + ``factorize`` + ``solve`` calls), iterations, objectives, and how many
factorizations went through the reduction and how many solves fell back to the full one.
Part 3 (``--sweep N``): iiwa-com cases ``0…N-1``, each solved once per method (alternating):
statuses, iterations, objectives, and the total time ratio over cases ``1…N-1``.

    python benchmarks/reduced_solve.py [--repeats 3] [--sweep 12] \
        [--out benchmarks/results/reduced-step]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.solvers.linear_solver import KKTSystem
from mbplan.solvers.reduced_step import ReducedKKTSystem

from mbplan.benchmarks.kkt_profile import warm_kkt
from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS

COMMAND = "python benchmarks/reduced_solve.py --sweep 12 --out benchmarks/results/reduced-step"
SOLVE_TASKS = [("iiwa-com", 3), *((f"chain{n}", 1) for n in (4, 8, 16, 32))]
METHODS = ("full", "reduced")
_KKT_CALLS = ("set_matrices", "factorize", "solve")


@contextmanager
def _kkt_clock(clock: dict[str, float]):
    """Timers on the outermost KKT calls of both classes (the reduced system calls the full
    one inside: counted once)."""
    saved = {(c, m): getattr(c, m) for c in (KKTSystem, ReducedKKTSystem) for m in _KKT_CALLS}
    depth = [0]

    def wrap(fn, name):
        def timed(self, *a, **kw):
            depth[0] += 1
            t0 = time.perf_counter()
            try:
                return fn(self, *a, **kw)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    clock[name] = clock.get(name, 0.0) + time.perf_counter() - t0

        return timed

    try:
        for (c, m), fn in saved.items():
            setattr(c, m, wrap(fn, m))
        yield
    finally:
        for (c, m), fn in saved.items():
            setattr(c, m, fn)


def kkt_parts(task: str, repeats: int, seed: int = 0) -> dict:
    """Part 1 (module docstring)."""
    problem, x0, _ = TASKS[task](0)
    blocks, diag, b = warm_kkt(problem, x0, seed)
    systems = {
        "full": KKTSystem(problem.n, problem.n_eq, problem.n_ineq),
        "reduced": ReducedKKTSystem(
            problem.n, problem.n_eq, problem.n_ineq, problem.elimination_plan, strict=True
        ),
    }
    times = {m: {k: [] for k in _KKT_CALLS} for m in METHODS}
    out = {}
    for rep in range(repeats + 1):  # the first round: analysis, compilation
        for m, kkt in systems.items():
            t0 = time.perf_counter()
            kkt.set_matrices(*blocks)
            t1 = time.perf_counter()
            inertia = kkt.factorize(diag, 1e-9)
            t2 = time.perf_counter()
            x, ratio = kkt.solve(b, 10, 1e-10)
            t3 = time.perf_counter()
            if rep:
                for k, dt in zip(_KKT_CALLS, (t1 - t0, t2 - t1, t3 - t2), strict=True):
                    times[m][k].append(1e3 * dt)
            out[m] = (inertia, x, ratio)
    red = systems["reduced"].reduction
    (i_f, x_f, r_f), (i_r, x_r, r_r) = out["full"], out["reduced"]
    return {
        "task": task,
        "dim": systems["full"].dim,
        "reduced_dim": red.kkt.dim,
        "mflop_full": systems["full"].analysis.flops / 1e6,
        "mflop_reduced_ldl": red.kkt.analysis.flops / 1e6,
        "inertia_equal": i_f == i_r,
        "step_rel_diff": float(np.abs(x_f - x_r).max() / np.abs(x_f).max()),
        "ratio": [r_f, r_r],
        "ms": {m: {k: min(v) for k, v in times[m].items()} for m in METHODS},
    }


def solves(task: str, cases: int, repeats: int) -> list[dict]:
    """Part 2 (module docstring): one row per case."""
    rows = []
    for case in range(cases):
        problem, x0, opts = TASKS[task](case)
        best: dict[str, dict] = {}
        for rep in range(repeats + 1):  # the first round: compilation, symbolic phases
            for m in METHODS:
                clock: dict[str, float] = {}
                with _kkt_clock(clock):
                    t0 = time.perf_counter()
                    res = solve_ripm(problem, x0, opts.replace(kkt_method=m))
                    wall = time.perf_counter() - t0
                if rep == 0:
                    continue
                row = {
                    "status": res.status.name,
                    "iterations": res.iterations,
                    "objective": res.objective,
                    "total_ms": 1e3 * wall,
                    "per_iter_ms": 1e3 * wall / max(res.iterations, 1),
                    "kkt_per_iter_ms": 1e3 * sum(clock.values()) / max(res.iterations, 1),
                    "factorizations": res.n_factorizations,
                }
                if m not in best or row["total_ms"] < best[m]["total_ms"]:
                    best[m] = row
        rows.append({"task": task, "case": case, **best})
        f, r = best["full"], best["reduced"]
        print(
            f"{task} case {case}: full {f['per_iter_ms']:.1f} ms/it ({f['iterations']} it), "
            f"reduced {r['per_iter_ms']:.1f} ms/it ({r['iterations']} it), "
            f"ratio {r['per_iter_ms'] / f['per_iter_ms']:.2f}",
            flush=True,
        )
    return rows


def _fraction_reduced(task: str, case: int) -> tuple[int, int, int]:
    """(factorizations through the reduction, all, fallback solves) of one reduced solve."""
    problem, x0, opts = TASKS[task](case)
    seen: list[ReducedKKTSystem] = []
    init = ReducedKKTSystem.__init__

    def spy(self, *a, **kw):
        init(self, *a, **kw)
        seen.append(self)

    ReducedKKTSystem.__init__ = spy
    try:
        solve_ripm(problem, x0, opts.replace(kkt_method="reduced"))
    finally:
        ReducedKKTSystem.__init__ = init
    k = seen[-1]
    return k.n_reduced, k.n_factorizations, k.n_fallbacks


def sweep(cases: int) -> list[dict]:
    """Part 3 (module docstring): one row per iiwa-com case."""
    rows = []
    for case in range(cases):
        problem, x0, opts = TASKS["iiwa-com"](case)
        row: dict = {"case": case}
        for m in METHODS:
            t0 = time.perf_counter()
            res = solve_ripm(problem, x0, opts.replace(kkt_method=m))
            row[m] = {
                "status": res.status.name,
                "iterations": res.iterations,
                "objective": res.objective,
                "total_ms": 1e3 * (time.perf_counter() - t0),
            }
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def sweep_markdown(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    same = sum(
        r["full"]["status"] == r["reduced"]["status"]
        and r["full"]["iterations"] == r["reduced"]["iterations"]
        for r in rows
    )
    dobj = max(
        abs(r["full"]["objective"] - r["reduced"]["objective"])
        / max(1.0, abs(r["full"]["objective"]))
        for r in rows
    )
    conv = {m: sum(r[m]["status"] == "CONVERGED" for r in rows) for m in METHODS}
    t = {m: sum(r[m]["total_ms"] for r in rows[1:]) for m in METHODS}
    ratio = t["reduced"] / t["full"] if t["full"] else float("nan")
    return [
        "",
        f"## iiwa-com cases 0…{len(rows) - 1}, one solve per method",
        "",
        f"Same status and iterations: {same}/{len(rows)}; converged full / reduced: "
        f"{conv['full']} / {conv['reduced']}; max objective rel. diff {dobj:.1e}; total time "
        f"(cases 1…) reduced / full: {ratio:.2f}.",
    ]


def markdown(parts: list[dict], rows: list[dict], load: str) -> str:
    lines = [
        '# RIPM with the joints eliminated (`kkt_method="reduced"`) vs the full KKT',
        "",
        f"`{COMMAND}` — load average at the start: {load}; min over repeats, interleaved.",
        "",
        "## One KKT at the warm start (ms, min)",
        "",
        "| task | dim → factorized K_r | Mflop full / reduced LDLᵀ | set_matrices full / red. | "
        "factorize full / red. | solve full / red. | factor+solve+set, red. / full | "
        "inertia equal | step rel. diff |",
        "|---|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for p in parts:
        f, r = p["ms"]["full"], p["ms"]["reduced"]
        ratio = sum(r.values()) / sum(f.values())
        lines.append(
            f"| {p['task']} | {p['dim']} → {p['reduced_dim']} | {p['mflop_full']:.1f} / "
            f"{p['mflop_reduced_ldl']:.1f} | {f['set_matrices']:.2f} / {r['set_matrices']:.2f} | "
            f"{f['factorize']:.2f} / {r['factorize']:.2f} | {f['solve']:.2f} / {r['solve']:.2f} | "
            f"{ratio:.2f} | {p['inertia_equal']} | {p['step_rel_diff']:.1e} |"
        )
    lines += [
        "",
        "## Whole RIPM solves (min total over repeats)",
        "",
        "| task | case | iterations full / red. | ms/iter full / red. | ratio | KKT ms/iter "
        "full / red. | objective rel. diff | reduced factorizations / all, fallbacks |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        f, r = row["full"], row["reduced"]
        dobj = abs(f["objective"] - r["objective"]) / max(1.0, abs(f["objective"]))
        nr, nall, nfb = row["reduced_counts"]
        lines.append(
            f"| {row['task']} | {row['case']} | {f['iterations']} / {r['iterations']} | "
            f"{f['per_iter_ms']:.1f} / {r['per_iter_ms']:.1f} | "
            f"{r['per_iter_ms'] / f['per_iter_ms']:.2f} | {f['kkt_per_iter_ms']:.1f} / "
            f"{r['kkt_per_iter_ms']:.1f} | {dobj:.1e} | {nr} / {nall}, {nfb} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--kkt-tasks", nargs="*", default=["iiwa-com", *(f"chain{n}" for n in (4, 8, 16, 32))]
    )
    ap.add_argument("--solve-tasks", nargs="*", default=[t for t, _ in SOLVE_TASKS])
    ap.add_argument("--sweep", type=int, default=0)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    parts = []
    for task in args.kkt_tasks:
        parts.append(kkt_parts(task, args.repeats))
        print(json.dumps(parts[-1], default=str), flush=True)
    rows = []
    cases = dict(SOLVE_TASKS)
    for task in args.solve_tasks:
        for row in solves(task, cases.get(task, 1), args.repeats):
            row["reduced_counts"] = _fraction_reduced(task, row["case"])
            rows.append(row)
    swept = sweep(args.sweep)
    text = markdown(parts, rows, load) + "\n".join(sweep_markdown(swept)) + "\n"
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "ripm-solves.md").write_text(text)
        (out / "ripm-solves.json").write_text(
            json.dumps({"kkt": parts, "solves": rows, "sweep": swept}, indent=1, default=str)
        )


if __name__ == "__main__":
    main()
