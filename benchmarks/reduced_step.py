"""Joint-eliminated (reduced per-knot) Newton step against the full sparse LDLᵀ, on the KKT
matrices of the speed benchmark's tasks (:mod:`mbplan.benchmarks.reduced_kkt`).

Per task: the KKT at the warm start with random multipliers (``y ~ N(0, 1)``, ``z, s`` in
``[0.5, 2]``, ``δ_w`` as given, ``δ_c = 0``); multiply-adds of the full AMD factorization and of
the reduction's parts plus the reduced AMD factorization, for the joint constraints eliminated
(``joints``) and for the joint forces eliminated too (``joints+forces``); inertia of both; the
step of both for a random right-hand side; interleaved A/B times (min and median of
``--repeats``): full factorize + solve against reduced factorize + solve; the prototype's
construction of the reduction (scipy, Python loops) once.

    python benchmarks/reduced_step.py [--tasks iiwa-com chain4 ...] [--repeats 7] \\
        [--out benchmarks/results/reduced-step]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.solvers.linear_solver import KKTSystem

from mbplan.benchmarks.reduced_kkt import ReducedKKT
from mbplan.formulations.maximal_layout import maximal_layout
from mbplan.tasks.speed import TASKS

COMMAND = "python benchmarks/reduced_step.py --out benchmarks/results/reduced-step"
TASK_NAMES = ["iiwa-com", "chain4", "chain8", "chain16", "chain32", "chain64"]
VARIANTS = {"joints": False, "joints+forces": True}


def _backward_error(K, x, b) -> float:
    """``‖Kx - b‖∞ / (‖K‖max ‖x‖∞ + ‖b‖∞)``."""
    r = np.abs(K @ x - b).max()
    return float(r / (np.abs(K).max() * np.abs(x).max() + np.abs(b).max()))


def _ms(times: list[float]) -> dict[str, float]:
    return {"min": 1e3 * min(times), "median": 1e3 * float(np.median(times))}


def compare(task: str, repeats: int, delta_w: float, seed: int = 0) -> list[dict]:
    """One row per variant (module docstring)."""
    problem, x0, _ = TASKS[task](0)
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.5, 2.0, problem.n_ineq)
    s = rng.uniform(0.5, 2.0, problem.n_ineq)
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    full = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    full.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    diag = np.concatenate([np.full(problem.n, delta_w), np.zeros(problem.n_eq), -s / z])
    inertia_full = full.factorize(diag, 1e-9)
    K = full.matrix().tocsr()
    b = rng.normal(size=K.shape[0])
    x_full = full.solve(b, 10, 1e-16)[0]  # refined to round-off, like the reduced step
    layout = maximal_layout(problem, ev.eq_jacobian)
    rows = []
    for variant, forces in VARIANTS.items():
        t0 = time.perf_counter()
        red = ReducedKKT(layout, K, forces=forces)
        build_s = time.perf_counter() - t0
        inertia_red = red.factorize()
        x_red = red.solve(b)
        times: dict[str, list[float]] = {k: [] for k in ("full", "reduced", "ff", "rf")}
        for _ in range(repeats):  # interleaved A/B
            t0 = time.perf_counter()
            full.factorize(diag, 1e-9)
            t1 = time.perf_counter()
            full.solve(b)
            times["full"].append(time.perf_counter() - t0)
            times["ff"].append(t1 - t0)
            t0 = time.perf_counter()
            red.factorize()
            t1 = time.perf_counter()
            red.solve(b)
            times["reduced"].append(time.perf_counter() - t0)
            times["rf"].append(t1 - t0)
        ldl = red.flops["reduced LDLT (AMD)"]
        total, total_tree = red.elimination_flops + ldl, red.elimination_flops_tree + ldl
        rows.append(
            {
                "task": task,
                "variant": variant,
                "delta_w": delta_w,
                "kkt_dim": K.shape[0],
                "reduced_dim": red.reduced.shape[0],
                "eliminated_pairs": red.m_eliminated,
                "full_amd_mflop": full.analysis.flops / 1e6,
                "reduction_mflop": {k: v / 1e6 for k, v in red.flops.items()},
                "reduced_total_mflop": total / 1e6,
                "reduced_total_tree_mflop": total_tree / 1e6,
                "flop_ratio_full_over_reduced": full.analysis.flops / total,
                "flop_ratio_full_over_reduced_tree": full.analysis.flops / total_tree,
                "inertia_full": None if inertia_full is None else list(vars(inertia_full).values()),
                "inertia_reduced": None
                if inertia_red is None
                else list(vars(inertia_red).values()),
                "step_rel_diff": float(np.abs(x_full - x_red).max() / np.abs(x_full).max()),
                "backward_error_full": _backward_error(K, x_full, b),
                "backward_error_reduced": _backward_error(K, x_red, b),
                "roundoff_dropped": red.dropped,
                "time_full_ms": _ms(times["full"]),
                "time_reduced_ms": _ms(times["reduced"]),
                "time_ratio_reduced_over_full_min": min(times["reduced"]) / min(times["full"]),
                "time_factor_full_ms": _ms(times["ff"]),
                "time_factor_reduced_ms": _ms(times["rf"]),
                "factor_time_ratio_reduced_over_full_min": min(times["rf"]) / min(times["ff"]),
                "reduction_build_s": build_s,
                "time_ratio_with_build_min": (build_s + min(times["reduced"])) / min(times["full"]),
            }
        )
    return rows


def markdown(rows: list[dict]) -> str:
    head = (
        "| KKT | eliminated | dim → reduced | full AMD | reduction | reduced LDLᵀ (AMD) "
        "| total | full / reduced | inertia equal | step rel. diff (backward error full, "
        "reduced) | LDLᵀ time, reduced / full (min) | factor+solve, reduced / full (min) "
        "| incl. building the reduction (prototype) |\n"
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|---:|---:|---:|\n"
    )
    lines = []
    for r in rows:
        ldl = r["reduction_mflop"]["reduced LDLT (AMD)"]
        tree = r["reduced_total_tree_mflop"]
        total = f"{r['reduced_total_mflop']:.1f}"
        ratio = f"{r['flop_ratio_full_over_reduced']:.1f}×"
        elim = f"{r['reduced_total_mflop'] - ldl:.1f}"
        if r["variant"] == "joints+forces":  # the tree-ordered solve count after the slash
            elim += f" / {tree - ldl:.1f}"
            total += f" / {tree:.1f}"
            ratio += f" / {r['flop_ratio_full_over_reduced_tree']:.1f}×"
        same = r["inertia_full"] == r["inertia_reduced"]
        lines.append(
            f"| {r['task']} | {r['variant']} | {r['kkt_dim']} → {r['reduced_dim']} "
            f"| {r['full_amd_mflop']:.1f} | {elim} | {ldl:.1f} | {total} | {ratio} | {same} "
            f"| {r['step_rel_diff']:.1e} ({r['backward_error_full']:.0e}, "
            f"{r['backward_error_reduced']:.0e}) "
            f"| {r['factor_time_ratio_reduced_over_full_min']:.3f} "
            f"| {r['time_ratio_reduced_over_full_min']:.2f} | {r['time_ratio_with_build_min']:.0f}× |"
        )
    return head + "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="*", default=TASK_NAMES)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--delta-w", type=float, default=1e-6)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for task in args.tasks:
        for row in compare(task, args.repeats, args.delta_w):
            print(json.dumps(row), flush=True)
            rows.append(row)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "results.json").write_text(json.dumps(rows, indent=1))
        text = (
            "# Joint-eliminated KKT vs the full AMD LDLᵀ (Mflop = 10⁶ multiply-adds)\n\n"
            f"`{COMMAND}` (δ_w = {args.delta_w:g}, δ_c = 0, random multipliers, "
            f"{args.repeats} interleaved repeats; `joints+forces` totals: as built / with "
            "`B⁻¹K_Yr` by back substitution over the tree)\n\n" + markdown(rows)
        )
        (out / "results.md").write_text(text)


if __name__ == "__main__":
    main()
