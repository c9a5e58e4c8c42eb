"""The KKT paths of the chain tasks side by side on one fixed KKT per task: the full
factorization (AMD, METIS with pivoting) and the joint-eliminated step (joints only or joints
and wrenches, in segments or not; ``K_r`` ordered by AMD or METIS), with each path's size and
flop counts.

The KKT of a task is the one of ``benchmarks/reduced_solve.py`` (warm start, random multipliers
``y ~ N(0, 1)``, ``z, s`` in ``[0.5, 2]``, ``δ_w = 1e-6``, ε = 1e-9). Per variant: min over
``--reps`` of ``set_matrices``, ``factorize`` and ``solve`` (10 refinement steps max, ratio
1e-10), the variants interleaved (alternating order per repetition; the machine is shared:
only ratios count); inertia and step against the first variant; flop counts:
``full`` the LDLᵀ's multiply-adds (:attr:`Analysis.flops`), ``K_r`` the reduced matrix's and
``TtW`` + ``HT`` the reduction's sparse products ``Tᵀ (H_f T)`` (lower half) and ``H_f T``
(multiply-adds of their patterns).

    python benchmarks/chain_paths.py --tasks chain4 chain16 chain64 --reps 3 \
        --out benchmarks/results/chain-s7/paths.json
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.solvers.linear_solver import KKTSystem
from mbplan.solvers.reduced_step import ReducedKKTSystem

from mbplan.benchmarks.kkt_profile import warm_kkt
from mbplan.formulations.maximal_layout import JointEliminationPlans
from mbplan.tasks.speed import TASKS

PIVOT = 1e-10
VARIANTS = ("full-amd", "full-metis", "joints-amd", "joints-metis", "wrench-amd", "wrench-metis")
"""``<path>[<segment>]-<ordering>``: ``full``, ``joints`` (joint blocks only), ``wrench`` (joint and
wrench blocks); ``segment``: :func:`joint_elimination_plan`'s (``wrench8-metis``: bodies at
depths 9, 17, … keep their maximal coordinates); METIS with pivoting (u = :data:`PIVOT`)."""
CALLS = ("set_matrices", "factorize", "solve")


def product_flops(a: sp.csr_matrix, b: sp.csr_matrix, lower: bool = False) -> float:
    """Multiply-adds of ``a @ b`` over the patterns (``lower``: about half, the lower part)."""
    col_a = np.bincount(a.indices, minlength=a.shape[1]).astype(float)
    flops = float(col_a @ np.diff(b.indptr).astype(float))
    return flops / 2 if lower else flops


def parse(variant: str) -> tuple[str, int | None, str]:
    """(path, segment, ordering) of a variant name (:data:`VARIANTS`)."""
    m = re.fullmatch(r"(full|joints|wrench)(\d*)-(amd|metis|auto)", variant)
    if m is None:
        raise SystemExit(f"unknown variant {variant!r}")
    return m[1], int(m[2]) if m[2] else None, m[3]


def system(problem: Any, variant: str) -> KKTSystem | ReducedKKTSystem:
    path, segment, ordering = parse(variant)
    pivot = 0.0 if ordering == "amd" else PIVOT
    dims = (problem.n, problem.n_eq, problem.n_ineq)
    if path == "full":
        return KKTSystem(*dims, ordering=ordering, pivot_threshold=pivot)
    plans = JointEliminationPlans(
        problem.elimination_plan.problem, forces=path == "wrench", segment=segment
    )
    return ReducedKKTSystem(*dims, plans, ordering=ordering, pivot_threshold=pivot, strict=True)


def sizes(kkt: KKTSystem | ReducedKKTSystem) -> dict[str, Any]:
    if isinstance(kkt, KKTSystem):
        return {
            "dim": kkt.dim,
            "mflop": kkt.analysis.flops / 1e6,
            "fill_m": kkt.analysis.nnz_l / 1e6,
        }
    red = kkt.reduction
    return {
        "dim": kkt.dim,
        "kr_dim": red.kkt.dim,
        "kr_mflop": red.kkt.analysis.flops / 1e6,
        "kr_fill_m": red.kkt.analysis.nnz_l / 1e6,
        "t_nnz_m": red.T.nnz / 1e6,
        "ttw_mflop": product_flops(red.Tt, red.W, lower=True) / 1e6,
        "ht_mflop": product_flops(red.hf, red.T) / 1e6,
    }


def run(task: str, variants: list[str], reps: int) -> dict[str, Any]:
    problem, x0, _ = TASKS[task](0)
    blocks, diag, rhs = warm_kkt(problem, x0)
    systems, out = {}, {}
    for v in variants:
        t0 = time.perf_counter()
        kkt = system(problem, v)
        kkt.set_matrices(*blocks)
        inertia = kkt.factorize(diag, 1e-9)
        x, ratio = kkt.solve(rhs, 10, 1e-10)
        first = time.perf_counter() - t0
        systems[v] = kkt
        out[v] = {
            **sizes(kkt),
            "first_call_s": first,
            "inertia": None if inertia is None else [inertia.positive, inertia.negative],
            "ratio": ratio,
            "x": x,
        }
        print(task, v, {k: w for k, w in out[v].items() if k != "x"}, flush=True)
    times = {v: {c: [] for c in CALLS} for v in variants}
    for rep in range(reps):
        for v in variants if rep % 2 == 0 else variants[::-1]:
            kkt = systems[v]
            t0 = time.perf_counter()
            kkt.set_matrices(*blocks)
            t1 = time.perf_counter()
            kkt.factorize(diag, 1e-9)
            t2 = time.perf_counter()
            kkt.solve(rhs, 10, 1e-10)
            t3 = time.perf_counter()
            for c, dt in zip(CALLS, (t1 - t0, t2 - t1, t3 - t2), strict=True):
                times[v][c].append(1e3 * dt)
    x_ref = out[variants[0]]["x"]
    for v in variants:
        x = out[v].pop("x")
        out[v]["step_rel_diff"] = float(np.abs(x - x_ref).max() / np.abs(x_ref).max())
        out[v]["ms"] = {c: min(t) for c, t in times[v].items()}
        out[v]["ms"]["kkt"] = sum(out[v]["ms"].values())
        if isinstance(systems[v], ReducedKKTSystem):
            out[v]["reduced"] = systems[v].n_reduced > 0 and systems[v].n_fallbacks == 0
    return {"task": task, "reps": reps, "variants": out}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=["chain4", "chain16", "chain64"])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS))
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for task in args.tasks:
        rows.append(run(task, args.variants, args.reps))
        for v, r in rows[-1]["variants"].items():
            ms = " ".join(f"{k} {t:.1f}" for k, t in r["ms"].items())
            print(f"{task:18s} {v:13s} {ms}  inertia {r['inertia']} diff {r['step_rel_diff']:.1e}")
        if args.out:
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
