"""AMD vs METIS vs auto on the speed tasks' KKT matrices: predicted multiply-adds and fill, the
time of the symbolic analysis (ordering + supernodal analysis), numeric factorization times
measured A/B interleaved in one process, and optionally whole RIPM solves with each order.

    python benchmarks/kkt_orderings.py [--tasks drone iiwa-com chain4 ...] [--reps 10]
        [--solves chain32 chain64] [--out benchmarks/results/kkt-orderings]

Factorization times: the KKT matrix at the task's warm start (Hessian and Jacobians from the
problem, diagonal ``1e-4`` on the primal, ``-1e-8`` on equality and ``-1`` on inequality rows,
static regularization 1e-9 as in the solver); every repetition factorizes with each order in
turn. Stability: the first KKT matrix of the RIPM's first iteration (``δ_w = 0``), captured from
a one-iteration solve, factorized with each order (inertia, or the pivot where it broke down).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.speed_tasks import TASKS
from mbplan.solvers import linear_solver as ls
from mbplan.solvers import solve_ripm
from mbplan.solvers.ldl_symbolic import Analysis
from mbplan.solvers.ordering import amd_order, metis_order
from mbplan.solvers.supernodal_ldl import SupernodalLDL

ORDERS = {"amd": amd_order, "metis": metis_order}


def _first_ripm_kkt(problem, x0, options) -> np.ndarray:
    """The factorized values of the first full KKT matrix of a RIPM solve (``δ_w = 0``)."""
    saved: list[np.ndarray] = []
    factorize = ls.KKTSystem.factorize
    dim = problem.n + problem.n_eq + problem.n_ineq

    def capture(self, diagonal, static_reg=0.0):
        out = factorize(self, diagonal, static_reg)
        if self.dim == dim and not saved and not np.any(diagonal[: self.n]):  # δ_w = 0
            saved.append(self._factor_data.copy())
        return out

    ls.KKTSystem.factorize = capture
    try:
        solve_ripm(problem, x0, options.replace(max_iter=1))
    finally:
        ls.KKTSystem.factorize = factorize
    return saved[0]


def _stability(systems: dict, values: np.ndarray) -> dict[str, str]:
    out = {}
    for o in ("amd", "metis"):
        solver = SupernodalLDL(systems[o].analysis)
        solver.d[:] = 0.0
        npos, nneg, ok = solver.factor(values)
        where = int(np.flatnonzero(solver.d == 0.0)[0]) if not ok else -1
        out[o] = f"({npos}, {nneg})" if ok else f"breakdown at pivot {where}"
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


def factor_ab(name: str, reps: int) -> dict:
    problem, x0, options = TASKS[name](0)
    ev = problem.evaluate(x0, 1.0, np.zeros(problem.n_eq), np.ones(problem.n_ineq))
    n, me, mi = problem.n, problem.n_eq, problem.n_ineq
    diag = np.concatenate([np.full(n, 1e-4), np.full(me, -1e-8), np.full(mi, -1.0)])
    systems = {}
    for o in ("amd", "metis", "auto"):
        kkt = ls.KKTSystem(n, me, mi, ordering=o)
        kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
        systems[o] = kkt
    auto = "amd" if systems["auto"].analysis is systems["amd"].analysis else "metis"
    times: dict[str, list[float]] = {"amd": [], "metis": []}
    inertia = {}
    for o in times:  # warm-up (compilation, first touch of the buffers)
        inertia[o] = systems[o].factorize(diag, 1e-9)
    rhs = np.random.default_rng(0).normal(size=n + me + mi)
    steps = {o: systems[o].solve(rhs)[0] for o in times}
    for _ in range(reps):
        for o, ts in times.items():
            t0 = time.perf_counter()
            systems[o].factorize(diag, 1e-9)
            ts.append(time.perf_counter() - t0)
    row = {
        "kkt_dim": n + me + mi,
        "auto": auto,
        "same_inertia": inertia["amd"] == inertia["metis"],
        "step_difference": float(
            np.max(np.abs(steps["amd"] - steps["metis"])) / np.max(np.abs(steps["amd"]))
        ),
        "analysis": _analysis_times(systems["amd"]._indptr, systems["amd"]._indices),
        "first_ripm_kkt": _stability(systems, _first_ripm_kkt(problem, x0, options)),
        "expected_inertia": f"({n}, {me + mi})",
    }
    for o, ts in times.items():
        a = systems[o].analysis
        row[o] = {
            "mflop": a.flops / 1e6,
            "nnz_factor": a.nnz_factor,
            "min_ms": 1e3 * min(ts),
            "median_ms": 1e3 * float(np.median(ts)),
            "gflops": a.flops / min(ts) / 1e9,
        }
    return row


def solve_ab(name: str) -> dict:
    problem, x0, options = TASKS[name](0)
    out = {}
    for o in ("amd", "metis", "amd", "metis"):  # the first of each: compilation and analysis
        opts = options.replace(kkt_ordering=o)
        t0 = time.perf_counter()
        res = solve_ripm(problem, x0, opts)
        out.setdefault(o, []).append(
            {
                "status": res.status.name,
                "iterations": res.iterations,
                "time_s": time.perf_counter() - t0,
                "objective": float(res.objective),
                "factorizations": res.n_factorizations,
            }
        )
    return out


def _markdown(rows: dict, solves: dict, command: str) -> str:
    lines = [
        "# KKT elimination orders: AMD vs METIS vs auto",
        "",
        f"Command: `{command}`",
        "",
        "Factorization times: min / median of the interleaved repetitions (same process, AMD and "
        "METIS alternating); GF/s = multiply-adds / min time; analysis = ordering + symbolic "
        "analysis (ms); same inertia, step rel. diff: the timed matrix solved with each order. "
        "First RIPM KKT: the first iteration's matrix (δ_w = 0) factorized with each order, "
        "(positive, negative) pivots or where the LDLᵀ without pivoting broke down.",
        "",
        "| task | KKT dim | AMD Mflop | METIS Mflop | auto picks | AMD ms (min / med) "
        "| METIS ms (min / med) | METIS / AMD (min) | AMD GF/s | METIS GF/s "
        "| analysis AMD / METIS ms | same inertia | step rel. diff "
        "| first RIPM KKT: expected | AMD | METIS |",
        "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---|---:|---|---|---|",
    ]
    for name, r in rows.items():
        a, m, an = r["amd"], r["metis"], r["analysis"]
        lines.append(
            f"| {name} | {r['kkt_dim']} | {a['mflop']:.1f} | {m['mflop']:.1f} | {r['auto']} "
            f"| {a['min_ms']:.2f} / {a['median_ms']:.2f} | {m['min_ms']:.2f} / {m['median_ms']:.2f} "
            f"| {m['min_ms'] / a['min_ms']:.2f} | {a['gflops']:.2f} | {m['gflops']:.2f} "
            f"| {sum(an['amd'].values()):.0f} / {sum(an['metis'].values()):.0f} "
            f"| {r['same_inertia']} | {r['step_difference']:.1e} | {r['expected_inertia']} "
            f"| {r['first_ripm_kkt']['amd']} | {r['first_ripm_kkt']['metis']} |"
        )
    if solves:
        lines += [
            "",
            "Whole RIPM solves (`speed_tasks.TASKS[name](0)`), the second solve of each order "
            "(the first includes compilation and the analysis), alternating AMD, METIS, AMD, METIS:",
            "",
            "| task | AMD iterations | METIS iterations | AMD factorizations "
            "| METIS factorizations | AMD s | METIS s | METIS / AMD | status "
            "| objective difference |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|",
        ]
        for name, s in solves.items():
            a, m = s["amd"][-1], s["metis"][-1]
            lines.append(
                f"| {name} | {a['iterations']} | {m['iterations']} | {a['factorizations']} "
                f"| {m['factorizations']} | {a['time_s']:.2f} "
                f"| {m['time_s']:.2f} | {m['time_s'] / a['time_s']:.2f} "
                f"| {a['status']} / {m['status']} | {abs(a['objective'] - m['objective']):.1e} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="*", default=list(TASKS))
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--solves", nargs="*", default=[])
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    command = "python benchmarks/kkt_orderings.py " + " ".join(sys.argv[1:])
    rows = {}
    for name in args.tasks:
        rows[name] = factor_ab(name, args.reps)
        print(name, json.dumps(rows[name]), flush=True)
    solves = {}
    for name in args.solves:
        solves[name] = solve_ab(name)
        print(name, json.dumps(solves[name]), flush=True)
    text = _markdown(rows, solves, command)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        data = {"factor": rows, "solves": solves, "command": command}
        (out / "summary.json").write_text(json.dumps(data, indent=1))
        (out / "results.md").write_text(text)


if __name__ == "__main__":
    main()
