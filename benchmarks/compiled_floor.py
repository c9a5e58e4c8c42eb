"""The floor of a compiled RIPM iteration on the drone, side by side with the RIPM's own.

One numba loop per case runs the kernels a main-phase RIPM iteration calls, in its order, with
no Python between them: the terms' evaluation with the Hessian (gather, site loops, sums),
the residuals (``measures``), the KKT matrix (scatter, diagonal, values), its LDLᵀ, one refined
solve (with the RIPM's options: at least one refinement step) and the retraction by the full
step. Three variants split the floor in situ: every stage, the evaluation (with the residuals
and the retraction) alone, and the evaluation with the factorization.

Left out, each a few microseconds: the finiteness and pattern checks, the fraction-to-boundary
and multiplier kernels, the line search's slope, trial evaluations without derivatives (0.3 per
drone iteration). It evaluates, factorizes and solves once per iteration (the RIPM: 1.0–1.35
times) and takes full Newton steps without inertia correction: on some cases the iterates run
away, which changes the values but hardly the kernels' work. A failing site loop or
factorization stops the run with an error. The loop reads private attributes of
``TrajectoryProblem`` and ``KKTSystem``: a measurement, not an API.

    python benchmarks/compiled_floor.py [--task drone] [--cases 20] [--iters 8] [--rounds 5]
        [--out benchmarks/results/compiled-floor/drone.json]

Results: docs/ripm-speed.md ("Session 15").
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numba as nb
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.solvers.kkt_scatter import matrix_values, scatter_blocks
from mbplan.solvers.ldl_kernels import ldl_factor
from mbplan.solvers.ldl_solve import refined_solve
from mbplan.solvers.linear_solver import KKTSystem
from mbplan.solvers.options import RIPMOptions
from mbplan.solvers.ripm_kernels import constraint_values, measures, newton_diagonal, newton_rhs

from mbplan.benchmarks.common import write_json
from mbplan.engine.site_table import run_site_loops
from mbplan.solvers.ripm import solve_ripm
from mbplan.tasks.speed import TASKS
from mbplan.transcription.evaluation_kernels import collect_derivatives, gather_inputs
from mbplan.transcription.packed import _retract


@nb.njit
def _iterations(
    iters, stages, packed0, evaluation, matrix, factor, retraction, settings
):  # pragma: no cover - numba
    """``iters`` iterations of the enabled ``stages`` (evaluate, factorize, solve); returns a
    checksum (so that nothing is optimized away), NaN if a site loop or the factorization
    failed. ``settings``: BLAS front rows, static regularization, refinement steps and ratio."""
    (z_gather, z_flat, lam_source, lam_flat, table, cost_jac, grad_cols, n, eq_res, eq_rows,
     n_eq, in_res, in_rows, n_in, eq_jac, eq_slot, eq_nnz, in_jac, in_slot, in_nnz, hess,
     hess_slot, hess_nnz, eq_indptr, eq_indices, in_indptr, in_indices) = evaluation  # fmt: skip
    (base, h_src, h_slot, e_slot, i_slot, diag_slot, full_src, full_data, values, full_indptr,
     full_indices, sign) = matrix  # fmt: skip
    (amap, sfirst, fptr, loff, uoff, zero_at, rptr, rel, cptr, child, sparent, direct, sent,
     lbuf, ubuf, d, piv, e, spiv, eptr, eidx, stats, perm, rows, work) = factor  # fmt: skip
    so3_off, so3_col, rn_dst, rn_src = retraction
    blas_rows, static_reg, max_refinement, ratio_max = settings
    no_shift = np.zeros(0)
    packed = packed0.copy()
    out = np.empty_like(packed)
    y, z, s = np.zeros(n_eq), np.ones(n_in), np.ones(n_in)
    r_d, r_c, c = np.empty(n), np.empty(n_eq + n_in), np.empty(n_eq + n_in)
    diagonal, rhs = np.zeros(n + n_eq + n_in), np.zeros(n + n_eq + n_in)
    sol = np.zeros(n + n_eq + n_in)
    grad, eq, ineq = np.zeros(n), np.zeros(n_eq), np.zeros(n_in)
    eq_data, in_data, hess_data = np.zeros(eq_nnz), np.zeros(in_nnz), np.zeros(hess_nnz)
    checksum = 0.0
    for _ in range(iters):
        if stages[0]:
            gather_inputs(packed, z_gather, z_flat, 1.0, y, z, lam_source, lam_flat)
            if run_site_loops(table) >= 0:
                return np.nan
            grad, eq, ineq, eq_data, in_data, hess_data = collect_derivatives(
                cost_jac, grad_cols, n, eq_res, eq_rows, n_eq, in_res, in_rows, n_in,
                eq_jac, eq_slot, eq_nnz, in_jac, in_slot, in_nnz, hess, hess_slot, hess_nnz,
            )  # fmt: skip
        checksum += constraint_values(eq, ineq, s, c)
        measures(
            grad, 1.0, eq_indptr, eq_indices, eq_data, y, in_indptr, in_indices, in_data, z,
            eq, ineq, s, r_d, r_c,
        )  # fmt: skip
        if stages[1]:
            scatter_blocks(base, hess_data, h_src, h_slot, eq_data, e_slot, in_data, i_slot)
            newton_diagonal(n, n_eq, 0.0, 0.0, s, z, diagonal)
            matrix_values(base, diag_slot, diagonal, n, static_reg, full_src, full_data, values)
            npos, _, _, ok = ldl_factor(
                values, amap, sfirst, fptr, loff, uoff, zero_at, rptr, rel, cptr, child,
                sparent, direct, sent, lbuf, ubuf, d, blas_rows, 0.0, 0.0, sign, piv, e, spiv,
                eptr, eidx, d, stats,
            )  # fmt: skip
            if not ok:
                return np.nan
            checksum += npos
        if stages[2]:
            newton_rhs(r_d, r_c, n_eq, s, z, 0.1, no_shift, rhs)
            sol, ratio = refined_solve(
                rhs, perm, sfirst, fptr, rows, loff, lbuf, d, piv, e, spiv, full_indptr,
                full_indices, full_data, work, max_refinement, ratio_max, 1,
            )  # fmt: skip
            checksum += ratio
        _retract(packed, sol[:n], so3_off, so3_col, rn_dst, rn_src, out)
        packed[:] = out
        y += sol[n : n + n_eq]
    return checksum


def _case_arrays(problem, x0) -> tuple:
    """The loop's arguments after ``iters`` and ``stages`` (the point, the evaluation's, the
    KKT matrix's, the factorization's and the retraction's arrays, the settings), from a problem
    evaluated once at ``x0``, and the ``KKTSystem`` whose workspace they are (kept alive: a
    released workspace would be handed to the next system)."""
    ev = problem.evaluate(x0, 1.0, np.zeros(problem.n_eq), np.zeros(problem.n_ineq))
    st = problem._structure
    if not hasattr(problem._bound["hessian"], "rows"):
        raise SystemExit("every term must be a compiled site loop (a C compiler is needed)")
    eqp, inp, hp = st.jac_patterns["eq"], st.jac_patterns["ineq"], st.hess_pattern
    evaluation = (
        st.z_gather, problem._z, st.lam_source, problem._lam, problem._bound["hessian"].rows,
        problem._jacobians["cost"], st.grad_cols, problem.n, problem._residuals["eq"],
        st.rows["eq"], problem.n_eq, problem._residuals["ineq"], st.rows["ineq"],
        problem.n_ineq, problem._jacobians["eq"], eqp.slot, eqp.nnz, problem._jacobians["ineq"],
        inp.slot, inp.nnz, problem._hessians, hp.slot, hp.nnz, ev.eq_jacobian.indptr,
        ev.eq_jacobian.indices, ev.ineq_jacobian.indptr, ev.ineq_jacobian.indices,
    )  # fmt: skip
    kkt = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    pat, ldl = kkt._pattern, kkt._solver
    a = ldl.a
    matrix = (
        kkt._base, pat.h_src, pat.h_slot, pat.e_slot, pat.i_slot, pat.diag_slot, pat.full_src,
        kkt._full_data, kkt._factor_data, pat.full_indptr, pat.full_indices, kkt._sign,
    )  # fmt: skip
    factor = (
        a.amap, a.sfirst, a.fptr, a.loff, a.uoff, a.zero_at, a.rptr, a.rel, a.cptr, a.child,
        a.sparent, a.direct, ldl.sent, ldl.lbuf, ldl.ubuf, ldl.d, ldl.piv, ldl.e, ldl.spiv,
        ldl._eptr, ldl._eidx, ldl.stats, a.perm, a.rows, ldl._work,
    )  # fmt: skip
    lay = problem.variables.layout
    retraction = (lay._so3_off, lay._so3_col, lay._rn_dst, lay._rn_src)
    packed = problem.variables.packed(x0).copy()
    o = RIPMOptions()
    settings = (
        ldl.blas_rows,
        o.static_regularization,
        o.max_refinement_steps,
        o.residual_ratio_max,
    )
    return (packed, evaluation, matrix, factor, retraction, settings), kkt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="drone", choices=[t for t in TASKS if "drone" in t])
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--iters", type=int, default=8, help="loop iterations per case")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (medians kept)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if not 1 <= args.cases <= 100:  # the benchmark's 100 sampled cases
        ap.error(f"--cases must be in 1..100, got {args.cases}")
    for name in ("iters", "rounds"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    cases = [TASKS[args.task](i) for i in range(args.cases)]
    setups = [_case_arrays(c[0], c[1]) for c in cases]
    variants = {
        "all": (1, 1, 1),
        "evaluate": (1, 0, 0),
        "evaluate+factorize": (1, 1, 0),
    }

    def loop_ms(stages: tuple[int, int, int]) -> float:
        flags = np.array(stages, np.int64)
        t0 = time.perf_counter()
        for arrays, _ in setups:
            if not np.isfinite(_iterations(args.iters, flags, *arrays)):
                raise SystemExit("a site loop or the factorization failed")
        return 1e3 * (time.perf_counter() - t0) / (len(setups) * args.iters)

    def ripm_ms() -> float:
        t0, its = time.perf_counter(), 0
        for c in cases:
            its += solve_ripm(*c).iterations
        return 1e3 * (time.perf_counter() - t0) / its

    for stages in variants.values():  # compile, warm up
        loop_ms(stages)
    ripm_ms()
    rounds: dict[str, list[float]] = {k: [] for k in [*variants, "ripm"]}
    for r in range(args.rounds):
        for name, stages in variants.items():
            rounds[name].append(loop_ms(stages))
        rounds["ripm"].append(ripm_ms())
        print(f"round {r}: " + ", ".join(f"{k} {v[-1]:.3f}" for k, v in rounds.items()))
    med = {k: float(np.median(v)) for k, v in rounds.items()}
    summary = {
        "task": args.task,
        "cases": args.cases,
        "iters": args.iters,
        "rounds": args.rounds,
        "ms_per_iteration_median": med,
        "ms_per_iteration_rounds": rounds,
        "floor_over_ripm": med["all"] / med["ripm"],
        "command": "python benchmarks/compiled_floor.py " + " ".join(sys.argv[1:]),
    }
    print(json.dumps({k: summary[k] for k in ("ms_per_iteration_median", "floor_over_ripm")}))
    if args.out:
        write_json(Path(args.out), summary)


if __name__ == "__main__":
    main()
