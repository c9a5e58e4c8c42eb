"""A/B of the LDLᵀ on fixed KKT matrices: a baseline tree's ``KKTSystem`` (its solver modules,
loaded from git) against the working tree's, interleaved in one process (the machine is
shared: only ratios count), min over the repetitions.

Systems (``--systems``): ``<task>`` is the full KKT of a speed task at its warm start (random
multipliers ``y ~ N(0, 1)``, ``z, s`` in ``[0.5, 2]``, ``δ_w = 1e-6``, ε = 1e-9, as
``benchmarks/reduced_solve.py``), solved as the Newton step does (10 refinement steps max,
ratio 1e-10); ``<task>-red`` is the joint-eliminated matrix ``K_r`` of the same KKT
(``ReducedKKTSystem.reduction.kkt``, ε = 1e-8), solved as the reduction does (one refinement
step, ratio 0). Per system: µs of ``factorize`` and ``solve`` (min), inertia and refinement
ratio of both trees, the largest relative difference of the solutions and the flop counts.

    python benchmarks/ldl_ab.py --baseline f686551 --systems drone iiwa-com iiwa-com-red \
        chain4 chain16 --reps 50 --out benchmarks/results/ldl/ab.json
"""

from __future__ import annotations

import argparse
import importlib
import json
import pickle
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mbplan.solvers.reduced_step import ReducedKKTSystem  # noqa: E402

from mbplan.benchmarks.common import modules_at  # noqa: E402
from mbplan.solvers import linear_solver  # noqa: E402
from mbplan.tasks.speed import TASKS  # noqa: E402

MODULES = (
    "ordering", "numba_borrow", "ldl_layout", "ldl_symbolic", "ldl_pivot", "ldl_dense",
    "ldl_kernels", "ldl_solve", "supernodal_ldl", "kkt_scatter", "kkt_pattern", "linear_solver",
)  # fmt: skip
CACHE = Path(tempfile.gettempdir()) / "mbplan-ldl-ab"


def baseline_kkt(rev: str) -> type:
    """``KKTSystem`` of commit ``rev`` (those of :data:`MODULES` that exist there; the rest of
    the package from the working tree), compiled in a per-commit temporary directory."""
    modules_at(rev, MODULES, "mbplan.solvers", "ldlbase_")
    return importlib.import_module("ldlbase_linear_solver").KKTSystem


def capture(name: str) -> dict[str, Any]:
    """The system ``name`` (module docstring): dims, blocks, diagonal, ε, rhs, solve args."""
    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"{name}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    task = name.removesuffix("-red")
    problem, x0, _ = TASKS[task](0)
    rng = np.random.default_rng(0)
    z, s = rng.uniform(0.5, 2.0, (2, problem.n_ineq))
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    blocks = (ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    dims = (problem.n, problem.n_eq, problem.n_ineq)
    diag = np.concatenate([np.full(problem.n, 1e-6), np.zeros(problem.n_eq), -s / z])
    rec = {"dims": dims, "blocks": blocks, "diag": diag, "reg": 1e-9, "args": (10, 1e-10)}
    if name.endswith("-red"):
        red = ReducedKKTSystem(*dims, problem.elimination_plan, strict=True)
        seen: dict[str, Any] = {}
        cls = linear_solver.KKTSystem
        saved = cls.set_matrices, cls.factorize

        def set_matrices(self, *b):
            seen["dims"], seen["blocks"] = (self.n, self.n_eq, self.n_ineq), b
            return saved[0](self, *b)

        def factorize(self, diagonal, reg):
            seen["diag"], seen["reg"] = diagonal.copy(), reg
            return saved[1](self, diagonal, reg)

        cls.set_matrices, cls.factorize = set_matrices, factorize
        try:
            red.set_matrices(*blocks)
            red.factorize(diag, 1e-9)
        finally:
            cls.set_matrices, cls.factorize = saved
        rec = {**seen, "args": (1, 0.0)}
        rec["blocks"] = tuple(b.copy() for b in rec["blocks"])
    rec["rhs"] = rng.normal(size=sum(rec["dims"]))
    path.write_bytes(pickle.dumps(rec))
    return rec


def run(name: str, reps: int, variants: dict[str, type]) -> dict[str, Any]:
    rec = capture(name)
    systems, out = {}, {}
    for v, cls in variants.items():
        kkt = cls(*rec["dims"])
        kkt.set_matrices(*rec["blocks"])
        inertia = kkt.factorize(rec["diag"], rec["reg"])
        x, ratio = kkt.solve(rec["rhs"], *rec["args"])
        systems[v] = kkt
        out[v] = {"inertia": None if inertia is None else [inertia.positive, inertia.negative],
                  "ratio": ratio, "x": x}  # fmt: skip
    times: dict[str, dict[str, list[float]]] = {v: {"factorize": [], "solve": []} for v in variants}
    order = list(variants)
    for rep in range(reps):
        for v in order if rep % 2 == 0 else order[::-1]:
            kkt = systems[v]
            t0 = time.perf_counter()
            kkt.factorize(rec["diag"], rec["reg"])
            t1 = time.perf_counter()
            kkt.solve(rec["rhs"], *rec["args"])
            t2 = time.perf_counter()
            times[v]["factorize"].append(1e6 * (t1 - t0))
            times[v]["solve"].append(1e6 * (t2 - t1))
    xa, xb = (out[v].pop("x") for v in variants)
    row = {
        "system": name,
        "dim": sum(rec["dims"]),
        "solution_rel_diff": float(np.abs(xa - xb).max() / np.abs(xa).max()),
        **{v: {**out[v], "mflop": systems[v].analysis.flops / 1e6,
               "supernodes": len(systems[v].analysis.sfirst) - 1,
               "nnz_factor": systems[v].analysis.nnz_factor,
               **{k: min(t) for k, t in times[v].items()}} for v in variants},
    }  # fmt: skip
    return row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default="f686551")
    ap.add_argument("--systems", nargs="+", default=["drone", "iiwa-com", "iiwa-com-red"])
    ap.add_argument("--reps", type=int, default=50)
    ap.add_argument("--out")
    a = ap.parse_args()
    variants = {"baseline": baseline_kkt(a.baseline), "new": linear_solver.KKTSystem}
    rows = []
    for name in a.systems:
        row = run(name, a.reps, variants)
        b, n = row["baseline"], row["new"]
        print(
            f"{name:14s} dim {row['dim']:6d} Mflop {b['mflop']:8.2f} → {n['mflop']:8.2f} "
            f"sn {b['supernodes']:5d} → {n['supernodes']:5d} | factorize {b['factorize']:9.1f} → "
            f"{n['factorize']:9.1f} µs ({n['factorize'] / b['factorize']:.2f}) | solve "
            f"{b['solve']:9.1f} → {n['solve']:9.1f} µs ({n['solve'] / b['solve']:.2f}) | inertia "
            f"{b['inertia']} {n['inertia']} ratio {b['ratio']:.1e} {n['ratio']:.1e} "
            f"dx {row['solution_rel_diff']:.1e}",
            flush=True,
        )
        rows.append(row)
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps({"command": " ".join(sys.argv), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
