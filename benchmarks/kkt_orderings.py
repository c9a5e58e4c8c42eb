"""AMD vs METIS vs auto on the speed tasks' KKT matrices, without and with pivoting inside the
supernodes: predicted multiply-adds and fill, the time of the symbolic analysis (ordering +
supernodal analysis), numeric factorization times measured A/B interleaved in one process, the
first RIPM KKT matrix (breakdowns, inertia, refinement steps), optionally whole RIPM solves and
per-iteration profiles with each variant.

    python benchmarks/kkt_orderings.py [--tasks drone iiwa-com chain4 ...] [--reps 10]
        [--pivot 1e-10] [--solves chain32 chain64] [--profile chain4 chain32 chain64]
        [--out benchmarks/results/kkt-orderings]

Factorization times: the KKT matrix at the task's warm start (Hessian and Jacobians from the
problem, diagonal ``1e-4`` on the primal, ``-1e-8`` on equality and ``-1`` on inequality rows,
static regularization 1e-9 as in the solver); every repetition factorizes with each variant in
turn. Stability: the first KKT matrix of the RIPM's first iteration (``δ_w = 0``), captured from
a one-iteration solve, factorized with each variant and static regularization ε (inertia or
breakdown, pivoting statistics, refinement steps to a residual ratio of 1e-10).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.solvers import solve_ripm
from mbplan.solvers.kkt import system as ls
from mbplan.solvers.kkt.ldl.symbolic import Analysis
from mbplan.solvers.kkt.ordering import amd_order, metis_order
from mbplan.tasks.speed import TASKS

ORDERS = {"amd": amd_order, "metis": metis_order}
PIVOT = 1e-10  # default threshold of the pivoted variants (--pivot)


def variants(u: float) -> dict[str, tuple[str, float]]:
    """Variant name -> (ordering, pivot threshold)."""
    return {"amd": ("amd", 0.0), "metis": ("metis", 0.0), "amd+piv": ("amd", u),
            "metis+piv": ("metis", u)}  # fmt: skip


def _first_ripm_kkt(problem, x0, options) -> tuple[tuple, np.ndarray]:
    """The blocks and diagonal of the first full KKT matrix of a RIPM solve (``δ_w = 0``)."""
    saved: dict = {}
    factorize, set_matrices = ls.KKTSystem.factorize, ls.KKTSystem.set_matrices
    dim = problem.n + problem.n_eq + problem.n_ineq

    def capture_blocks(self, *blocks):
        if self.dim == dim and "diagonal" not in saved:
            saved["blocks"] = tuple(b.copy() if b is not None else None for b in blocks)
        return set_matrices(self, *blocks)

    def capture(self, diagonal, static_reg=0.0):
        if self.dim == dim and "diagonal" not in saved and not np.any(diagonal[: self.n]):
            saved["diagonal"] = diagonal.copy()
        return factorize(self, diagonal, static_reg)

    ls.KKTSystem.factorize, ls.KKTSystem.set_matrices = capture, capture_blocks
    try:
        solve_ripm(problem, x0, options.replace(max_iter=1, kkt_method="full"))
    finally:
        ls.KKTSystem.factorize, ls.KKTSystem.set_matrices = factorize, set_matrices
    return saved["blocks"], saved["diagonal"]


def _stability(problem, blocks, diagonal, u: float, eps: float) -> dict[str, dict]:
    """Each variant on the first RIPM KKT matrix with static regularization ``eps``."""
    rhs = np.random.default_rng(1).normal(size=diagonal.shape[0])
    out = {}
    for name, (order, piv) in variants(u).items():
        kkt = ls.KKTSystem(problem.n, problem.n_eq, problem.n_ineq, ordering=order,
                           pivot_threshold=piv)  # fmt: skip
        kkt.set_matrices(*blocks)
        inertia = kkt.factorize(diagonal, eps)
        row: dict = {"inertia": None if inertia is None else [inertia.positive, inertia.negative]}
        if inertia is not None:
            ratios = [kkt.solve(rhs, j, 0.0)[1] for j in range(6)]
            row["ratios"] = ratios
            row["steps"] = next((j for j, r in enumerate(ratios) if r <= 1e-10), None)
            row |= kkt.pivot_stats
        out[name] = row
    return out


def _analysis_times(indptr: np.ndarray, indices: np.ndarray) -> dict[str, dict[str, float]]:
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    out = {}
    for name, order in ORDERS.items():
        t0 = time.perf_counter()
        perm = order(indptr, indices)
        t1 = time.perf_counter()
        Analysis(n, rows, indices, perm)
        out[name] = {"order_ms": 1e3 * (t1 - t0), "symbolic_ms": 1e3 * (time.perf_counter() - t1)}
    return out


def factor_ab(name: str, reps: int, u: float, eps_list: list[float]) -> dict:
    problem, x0, options = TASKS[name](0)
    ev = problem.evaluate(x0, 1.0, np.zeros(problem.n_eq), np.ones(problem.n_ineq))
    n, me, mi = problem.n, problem.n_eq, problem.n_ineq
    diag = np.concatenate([np.full(n, 1e-4), np.full(me, -1e-8), np.full(mi, -1.0)])
    systems = {}
    for v, (o, piv) in (variants(u) | {"auto": ("auto", 0.0)}).items():
        kkt = ls.KKTSystem(n, me, mi, ordering=o, pivot_threshold=piv)
        kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
        systems[v] = kkt
    auto = "amd" if systems["auto"].analysis is systems["amd"].analysis else "metis"
    del systems["auto"]
    times: dict[str, list[float]] = {v: [] for v in systems}
    inertia = {}
    for v in times:  # warm-up (compilation, first touch of the buffers)
        inertia[v] = systems[v].factorize(diag, 1e-9)
    rhs = np.random.default_rng(0).normal(size=n + me + mi)
    steps = {v: systems[v].solve(rhs)[0] for v in times}
    for _ in range(reps):
        for v, ts in times.items():
            t0 = time.perf_counter()
            systems[v].factorize(diag, 1e-9)
            ts.append(time.perf_counter() - t0)
    blocks, first = _first_ripm_kkt(problem, x0, options)
    row = {
        "kkt_dim": n + me + mi,
        "auto": auto,
        "same_inertia": all(inertia[v] == inertia["amd"] for v in times),
        "step_difference": max(
            float(np.max(np.abs(steps["amd"] - steps[v])) / np.max(np.abs(steps["amd"])))
            for v in times
        ),
        "analysis": _analysis_times(systems["amd"]._indptr, systems["amd"]._indices),
        "first_ripm_kkt": {
            f"{eps:g}": _stability(problem, blocks, first, u, eps) for eps in eps_list
        },
        "expected_inertia": [n, me + mi],
    }
    for v, ts in times.items():
        a = systems[v].analysis
        row[v] = {
            "mflop": a.flops / 1e6,
            "nnz_factor": a.nnz_factor,
            "min_ms": 1e3 * min(ts),
            "median_ms": 1e3 * float(np.median(ts)),
            "gflops": a.flops / min(ts) / 1e9,
        }
    return row


PROFILE_VARIANTS = ("amd", "amd+piv", "metis+piv")


def profile_ab(name: str, u: float, rounds: int, names: list[str]) -> dict:
    """Per-iteration profiles (:func:`~mbplan.benchmarks.kkt_profile.profile_solve`) of whole
    RIPM solves with each variant of ``names``, alternating, ``rounds`` times."""
    problem, x0, options = TASKS[name](0)
    out: dict[str, list[dict]] = {}
    for _ in range(rounds):
        for v in names:
            o, piv = variants(u)[v]
            opts = options.replace(kkt_ordering=o, kkt_pivot_threshold=piv)
            out.setdefault(v, []).append(profile_solve(problem, x0, opts))
    return out


def _fmt_stability(r: dict) -> str:
    if r["inertia"] is None:
        return "breakdown"
    text = f"({r['inertia'][0]}, {r['inertia'][1]}), {r['steps']}"
    if r.get("pivoted_fronts"):
        text += f"; {r['pivoted_fronts']} / {r['two_by_two']} / {r['perturbed']}"
    return text


def _markdown(rows: dict, profiles: dict, command: str, u: float) -> str:
    vs = list(variants(u))
    lines = [
        "# KKT elimination orders: AMD vs METIS, without and with pivoting inside supernodes",
        "",
        f"Command: `{command}`",
        "",
        f"`+piv`: threshold pivoting inside each supernode, u = {u:g} (`KKTSystem(..., "
        "pivot_threshold=u)`). Factorization: the KKT at the warm start (δ = 1e-4), min / "
        "median ms of the interleaved repetitions (same process, variants alternating); "
        "analysis = ordering + symbolic analysis (ms).",
        "",
        "| task | KKT dim | AMD Mflop | METIS Mflop | auto picks | "
        + " | ".join(f"{v} ms" for v in vs)
        + " | METIS+piv / AMD | AMD+piv / AMD | analysis AMD / METIS ms | same inertia "
        "| step rel. diff |",
        "|---|---:|---:|---:|---|" + "---:|" * (len(vs) + 3) + "---|---:|",
    ]
    for name, r in rows.items():
        an = r["analysis"]
        lines.append(
            f"| {name} | {r['kkt_dim']} | {r['amd']['mflop']:.1f} | {r['metis']['mflop']:.1f} "
            f"| {r['auto']} | "
            + " | ".join(f"{r[v]['min_ms']:.2f} / {r[v]['median_ms']:.2f}" for v in vs)
            + f" | {r['metis+piv']['min_ms'] / r['amd']['min_ms']:.2f} "
            f"| {r['amd+piv']['min_ms'] / r['amd']['min_ms']:.2f} "
            f"| {sum(an['amd'].values()):.0f} / {sum(an['metis'].values()):.0f} "
            f"| {r['same_inertia']} | {r['step_difference']:.1e} |"
        )
    lines += [
        "",
        "First RIPM KKT matrix (δ_w = 0, captured from a one-iteration solve), per static "
        "regularization ε: inertia (positive, negative) or breakdown, refinement steps to a "
        "residual ratio ≤ 1e-10 (None: not within 5); with pivoting: pivoted fronts / 2 × 2 "
        "pivots / perturbed pivots.",
        "",
        "| task | ε | expected | " + " | ".join(vs) + " |",
        "|---|---|---|" + "---|" * len(vs),
    ]
    for name, r in rows.items():
        for eps, st in r["first_ripm_kkt"].items():
            exp = r["expected_inertia"]
            lines.append(
                f"| {name} | {eps} | ({exp[0]}, {exp[1]}) | "
                + " | ".join(_fmt_stability(st[v]) for v in vs)
                + " |"
            )
    if profiles:
        keys = ("factorize_ms", "solve_ms", "per_iter_ms")
        lines += [
            "",
            "Whole RIPM solves (`speed_tasks.TASKS[name](0)`, `kkt_profile.profile_solve`: a "
            "warm-up solve, then the profiled one), variants alternating; ms per iteration, "
            "min over rounds; solves/iter = KKT solves per iteration:",
            "",
            "| task | variant | status | iterations | factorizations / iter | factorize ms "
            "| solve ms | ms / iter |",
            "|---|---|---|---:|---:|---:|---:|---:|",
        ]
        for name, prof in profiles.items():
            for v, runs in prof.items():
                best = {k: min(run[k] for run in runs) for k in keys}
                lines.append(
                    f"| {name} | {v} | {runs[-1]['status']} | {runs[-1]['iterations']} "
                    f"| {runs[-1]['factorize_per_iter']:.2f} | {best['factorize_ms']:.1f} "
                    f"| {best['solve_ms']:.1f} | {best['per_iter_ms']:.1f} |"
                )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="*", default=list(TASKS))
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--pivot", type=float, default=PIVOT)
    ap.add_argument("--eps", type=float, nargs="*", default=[1e-9, 1e-12])
    ap.add_argument("--profile", nargs="*", default=[])
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--variants", nargs="*", default=list(PROFILE_VARIANTS))
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    command = "python benchmarks/kkt_orderings.py " + " ".join(sys.argv[1:])
    rows = {}
    for name in args.tasks:
        rows[name] = factor_ab(name, args.reps, args.pivot, args.eps)
        print(name, json.dumps(rows[name]), flush=True)
    profiles = {}
    for name in args.profile:
        profiles[name] = profile_ab(name, args.pivot, args.rounds, args.variants)
        print(name, json.dumps(profiles[name]), flush=True)
    text = _markdown(rows, profiles, command, args.pivot)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        data = {"factor": rows, "profiles": profiles, "command": command}
        (out / "summary.json").write_text(json.dumps(data, indent=1))
        (out / "results.md").write_text(text)


if __name__ == "__main__":
    main()
