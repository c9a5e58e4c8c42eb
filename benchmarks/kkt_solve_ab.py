"""A/B of the KKT solve path inside RIPM solves: a baseline commit's ``KKTSystem`` (its
``linear_solver.py``, ``ldl_kernels.py`` and, where they exist, ``supernodal_ldl.py`` and
``ldl_pivot.py``, loaded from git) against the working tree's, on
the same problems, interleaved in one process (the machine is shared: only ratios count).

Per task: ms per call of ``set_matrices`` (assembly), ``factorize`` and ``solve`` (triangular
solves with refinement) inside the solves, iterations of both (must be equal) and the largest
difference of the iteration histories; then the same calls on the captured KKT systems of one
solve, back to back (less noise from the other processes on the machine).

    python benchmarks/kkt_solve_ab.py --baseline 792e4a5 --tasks drone iiwa-com chain16 \
        --reps 7 --out benchmarks/results/kkt-solve/results.md
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mbplan.benchmarks.common import modules_at  # noqa: E402
from mbplan.solvers import linear_solver, ripm  # noqa: E402
from mbplan.tasks.speed import TASKS  # noqa: E402

MAX_SYSTEMS = 6  # captured KKT systems timed per case (evenly spaced over the solve)
METHODS = {"set_matrices": "assembly", "factorize": "factorize", "solve": "solve"}


BASELINE_MODULES = (
    "numba_borrow", "ldl_layout", "ldl_symbolic", "ldl_pivot", "ldl_dense", "ldl_kernels",
    "ldl_solve", "supernodal_ldl", "kkt_scatter", "kkt_pattern", "linear_solver",
)  # fmt: skip


def baseline_kkt(rev: str) -> type:
    """``KKTSystem`` of commit ``rev`` (those of its modules :data:`BASELINE_MODULES` that exist
    at ``rev``; the rest of the package from the working tree), compiled in a per-commit
    temporary directory."""
    modules_at(rev, BASELINE_MODULES, "mbplan.solvers", "baseline_")
    module = importlib.import_module("baseline_linear_solver")

    class Baseline(module.KKTSystem):
        """The baseline, accepting the RIPM's ``pivot_threshold`` (0 only: no pivoting)."""

        def __init__(self, *args: Any, pivot_threshold: float = 0.0, **kw: Any) -> None:
            if pivot_threshold:
                raise ValueError("the baseline KKTSystem does not pivot")
            super().__init__(*args, **kw)

    return Baseline


def timed_solve(kkt_class: type, problem: Any, x0: Any, options: Any) -> tuple[Any, dict]:
    """One RIPM solve with ``kkt_class`` as its KKT system and timers on its methods."""
    clock = {k: 0.0 for k in METHODS.values()} | {"n_" + k: 0 for k in METHODS.values()}
    saved = {name: getattr(kkt_class, name) for name in METHODS}

    def wrap(name: str):
        fn, key = saved[name], METHODS[name]

        def timed(self, *args, **kw):
            t0 = time.perf_counter()
            try:
                return fn(self, *args, **kw)
            finally:
                clock[key] += time.perf_counter() - t0
                clock["n_" + key] += 1

        return timed

    ripm.KKTSystem = kkt_class
    try:
        for name in METHODS:
            setattr(kkt_class, name, wrap(name))
        res = ripm.solve_ripm(problem, x0, options)
    finally:
        for name, fn in saved.items():
            setattr(kkt_class, name, fn)
        ripm.KKTSystem = linear_solver.KKTSystem
    return res, clock


def captured_systems(problem: Any, x0: Any, options: Any) -> list[dict]:
    """The KKT systems of one RIPM solve (blocks, diagonal, right-hand side of every solve)."""
    cls, records, current = linear_solver.KKTSystem, [], {}
    saved = {name: getattr(cls, name) for name in METHODS}

    def set_matrices(self, *blocks):
        current["dims"], current["blocks"] = (self.n, self.n_eq, self.n_ineq), blocks
        return saved["set_matrices"](self, *blocks)

    def factorize(self, *args):
        current["factorize"] = args
        return saved["factorize"](self, *args)

    def solve(self, rhs, *args):
        records.append(dict(current, rhs=rhs.copy(), args=args))
        return saved["solve"](self, rhs, *args)

    try:
        cls.set_matrices, cls.factorize, cls.solve = set_matrices, factorize, solve
        ripm.solve_ripm(problem, x0, options)
    finally:
        for name, fn in saved.items():
            setattr(cls, name, fn)
    return records


def hot_loop(records: list[dict], reps: int, variants: dict[str, type]) -> dict:
    """ms per call of each method on the captured systems, called back to back (``reps``
    rounds, variants alternating; the solve right after its factorization), and the largest
    relative difference of the solutions."""
    systems = {}
    for v, cls in variants.items():
        systems[v] = []
        for r in records:
            kkt = cls(*r["dims"])
            kkt.set_matrices(*r["blocks"])
            kkt.factorize(*r["factorize"])
            systems[v].append(kkt)
    sols = {
        v: [k.solve(r["rhs"], *r["args"])[0] for k, r in zip(ks, records, strict=True)]
        for v, ks in systems.items()
    }
    a, b = sols.values()
    diff = max(
        float(np.max(np.abs(x - y)) / max(np.max(np.abs(x)), 1e-300))
        for x, y in zip(a, b, strict=True)
    )
    times = {v: {k: [] for k in METHODS.values()} for v in variants}
    order = list(variants)
    for rep in range(reps):
        for v in order if rep % 2 == 0 else order[::-1]:
            for kkt, r in zip(systems[v], records, strict=True):
                t0 = time.perf_counter()
                kkt.set_matrices(*r["blocks"])
                t1 = time.perf_counter()
                kkt.factorize(*r["factorize"])
                t2 = time.perf_counter()
                kkt.solve(r["rhs"], *r["args"])
                t3 = time.perf_counter()
                for key, dt in zip(METHODS.values(), (t1 - t0, t2 - t1, t3 - t2), strict=True):
                    times[v][key].append(1e3 * dt)
    out = {v: {k: float(np.median(t)) for k, t in times[v].items()} for v in variants}
    return {"ms_per_call": out, "solution_rel_diff": diff, "systems": len(records)}


def run_task(name: str, cases: int, reps: int, variants: dict[str, type]) -> dict:
    rows = []
    for i in range(cases):
        problem, x0, options = TASKS[name](i)
        results = {v: timed_solve(cls, problem, x0, options)[0] for v, cls in variants.items()}
        iters = {v: r.iterations for v, r in results.items()}
        a, b = (results[v].history.kkt_error for v in variants)
        diff = float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.maximum(np.abs(a), 1e-300)))
        per_call = {v: {k: [] for k in METHODS.values()} for v in variants}
        order = list(variants)
        for rep in range(reps):
            for v in order if rep % 2 == 0 else order[::-1]:
                _, clock = timed_solve(variants[v], problem, x0, options)
                for k in METHODS.values():
                    per_call[v][k].append(1e3 * clock[k] / max(clock["n_" + k], 1))
                calls = {k: clock["n_" + k] / max(iters[v], 1) for k in METHODS.values()}
        records = captured_systems(problem, x0, options)
        records = records[:: -(-len(records) // MAX_SYSTEMS)]
        rows.append(
            {
                "case": i,
                "hot": hot_loop(records, reps, variants),
                "iterations": iters,
                "history_rel_diff": diff,
                "calls_per_iter": calls,
                "ms_per_call": {
                    v: {k: float(np.median(t)) for k, t in per_call[v].items()} for v in variants
                },
            }
        )
        print(name, rows[-1], flush=True)
    return {"task": name, "dim": problem.n + problem.n_eq + problem.n_ineq, "cases": rows}


def markdown(tasks: list[dict], command: str, baseline: str) -> str:
    lines = [
        "# KKT solve path: baseline vs working tree, inside RIPM solves",
        "",
        f"Command: `{command}`  ",
        f"Baseline: commit `{baseline}` (`linear_solver.py`, `ldl_kernels.py`). Interleaved in one "
        "process on a shared machine; medians over the repetitions of ms per call.",
        "",
        "| task | KKT dim | case | iters base / new | history rel. diff | solves/iter | "
        "solve base → new [ms] | ratio | assembly base → new [ms] | ratio | factorize base → new "
        "[ms] | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for t in tasks:
        for r in t["cases"]:
            base, new = r["ms_per_call"]["baseline"], r["ms_per_call"]["new"]
            cells = []
            for k in ("solve", "assembly", "factorize"):
                cells += [f"{base[k]:.3f} → {new[k]:.3f}", f"{new[k] / base[k]:.2f}"]
            it = r["iterations"]
            lines.append(
                f"| {t['task']} | {t['dim']} | {r['case']} | {it['baseline']} / {it['new']} | "
                f"{r['history_rel_diff']:.1e} | {r['calls_per_iter']['solve']:.2f} | "
                + " | ".join(cells)
                + " |"
            )
    lines += [
        "",
        "The same KKT systems (every solve of the case's RIPM run, captured) called back to back "
        "outside the solver: ms per call, medians.",
        "",
        "| task | case | systems | max rel. diff of solutions | solve base → new [ms] | ratio | "
        "assembly base → new [ms] | ratio | factorize base → new [ms] | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for t in tasks:
        for r in t["cases"]:
            hot = r["hot"]
            base, new = hot["ms_per_call"]["baseline"], hot["ms_per_call"]["new"]
            cells = []
            for k in ("solve", "assembly", "factorize"):
                cells += [f"{base[k]:.3f} → {new[k]:.3f}", f"{new[k] / base[k]:.2f}"]
            lines.append(
                f"| {t['task']} | {r['case']} | {hot['systems']} | {hot['solution_rel_diff']:.1e} | "
                + " | ".join(cells)
                + " |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default="792e4a5")
    ap.add_argument("--tasks", nargs="*", default=["drone", "iiwa-com", "chain16"])
    ap.add_argument("--cases", type=int, default=1)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    variants = {"baseline": baseline_kkt(args.baseline), "new": linear_solver.KKTSystem}
    tasks = [run_task(name, args.cases, args.reps, variants) for name in args.tasks]
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        command = "python benchmarks/kkt_solve_ab.py " + " ".join(sys.argv[1:])
        out.write_text(markdown(tasks, command, args.baseline))
        out.with_suffix(".json").write_text(__import__("json").dumps(tasks, indent=1))


if __name__ == "__main__":
    main()
