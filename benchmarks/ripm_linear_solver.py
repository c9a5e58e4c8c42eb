"""Micro-benchmark: sparse symmetric-indefinite factorizations for the RIPM's KKT matrix.

The matrices are the reduced KKT systems (see ``mbplan.solvers.ripm``) of the block-banded
optimal-control NLP ``mbplan.solvers.examples.BandedControlNLP`` (24 states, 7 inputs per knot,
horizon chosen for sizes 500 … 8000), i.e. the structure of a trajectory optimization. For each
candidate we time one numeric (re)factorization with the ordering already computed, how the
inertia is obtained, and a solve. Prints markdown tables; a second table times whole RIPM
iterations at horizon 40.

    python benchmarks/ripm_linear_solver.py [--quick]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time

import casadi as ca
import numpy as np
import qdldl
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mbplan.solvers.examples import BandedControlNLP
from mbplan.solvers.linear_solver import KKTSystem

from mbplan.benchmarks.common import median_time
from mbplan.solvers import solve_ripm

NX, NU = 24, 7


def kkt_matrix(horizon: int) -> tuple[KKTSystem, np.ndarray, sp.csc_matrix]:
    """The RIPM's KKT system at the initial guess (with Lagrangian curvature from y ≠ 0)."""
    prob = BandedControlNLP(NX, NU, horizon)
    x0 = prob.initial_guess()
    rng = np.random.default_rng(0)
    ev = prob.evaluate(x0, 1.0, rng.normal(size=prob.n_eq), np.ones(prob.n_ineq))
    kkt = KKTSystem(prob.n, prob.n_eq, prob.n_ineq)
    kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    s = np.maximum(-ev.ineq, 1e-2)
    # as factorized by the RIPM: δ_w = 1e-4 and the static regularization -1e-9 on the y block
    diag = np.concatenate([np.full(prob.n, 1e-4), np.full(prob.n_eq, -1e-9), -s])
    kkt.factorize(diag)
    return kkt, diag, kkt.matrix()


def time_qdldl(kkt: KKTSystem, diag: np.ndarray, full: sp.csc_matrix) -> dict[str, float]:
    upper = sp.triu(full, format="csc")
    t0 = time.perf_counter()
    solver = qdldl.Solver(upper, upper=True)
    first = time.perf_counter() - t0
    rhs = np.ones(full.shape[0])
    return {
        "first (AMD+symbolic+numeric)": first,
        "refactorization": median_time(lambda: solver.update(upper, upper=True)),
        "inertia": median_time(lambda: np.count_nonzero(solver.factors()[1] < 0)),
        "solve": median_time(lambda: solver.solve(rhs)),
        "KKTSystem.factorize (assembly+update+inertia)": median_time(lambda: kkt.factorize(diag)),
    }


@contextlib.contextmanager
def _quiet_stdout():
    """MUMPS prints banners from C: silence file descriptor 1 while it runs."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


def time_casadi(full: sp.csc_matrix, plugin: str) -> dict[str, float]:
    with _quiet_stdout():
        return _time_casadi(full, plugin)


def _time_casadi(full: sp.csc_matrix, plugin: str) -> dict[str, float]:
    full = full.copy()
    full.sort_indices()
    sparsity = ca.Sparsity(*full.shape, full.indptr.tolist(), full.indices.tolist())
    matrix = ca.DM(sparsity, full.data)
    linsol = ca.Linsol("linsol", plugin, sparsity)
    linsol.sfact(matrix)
    rhs = ca.DM(np.ones(full.shape[0]))
    out = {"refactorization": median_time(lambda: linsol.nfact(matrix), min_repeats=3)}
    try:
        out["inertia"] = median_time(lambda: linsol.neig(matrix), min_repeats=3)
    except RuntimeError:
        out["inertia"] = float("nan")  # the plugin does not report it
    out["solve"] = median_time(lambda: linsol.solve(matrix, rhs), min_repeats=3)
    return out


def time_splu(full: sp.csc_matrix) -> dict[str, float]:
    lu = spla.splu(full)
    rhs = np.ones(full.shape[0])
    return {
        "refactorization": median_time(lambda: spla.splu(full), min_repeats=3),
        "inertia": float("nan"),
        "solve": median_time(lambda: lu.solve(rhs)),
    }


def ripm_iteration_time(horizon: int) -> tuple[int, int, float, float]:
    prob = BandedControlNLP(NX, NU, horizon)
    x0 = prob.initial_guess()
    res = solve_ripm(prob, x0)
    return prob.n + prob.n_eq + prob.n_ineq, res.iterations, res.wall_time_s, res.objective


def _ms(t: float) -> str:
    return "n/a" if np.isnan(t) else f"{1e3 * t:.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="sizes up to ~2000 only")
    args = parser.parse_args()
    horizons = [7, 14, 29] if args.quick else [7, 14, 29, 58, 115]

    rows = []
    for horizon in horizons:
        kkt, diag, full = kkt_matrix(horizon)
        dim, nnz = full.shape[0], full.nnz
        rows.append((dim, nnz, "qdldl (AMD, LDLᵀ without pivoting)", time_qdldl(kkt, diag, full)))
        rows.append((dim, nnz, "casadi ldl", time_casadi(full, "ldl")))
        rows.append((dim, nnz, "casadi mumps", time_casadi(full, "mumps")))
        rows.append((dim, nnz, "scipy splu (SuperLU, LU)", time_splu(full)))

    print("## Factorization of the RIPM KKT matrix (times in ms, median)\n")
    print("| dim | nnz (full) | solver | refactorization | inertia | solve | notes |")
    print("|---:|---:|---|---:|---:|---:|---|")
    for dim, nnz, name, t in rows:
        notes = []
        if "first (AMD+symbolic+numeric)" in t:
            notes.append(f"first factorization {_ms(t['first (AMD+symbolic+numeric)'])}")
            key = "KKTSystem.factorize (assembly+update+inertia)"
            notes.append(f"KKTSystem.factorize {_ms(t[key])}")
        print(
            f"| {dim} | {nnz} | {name} | {_ms(t['refactorization'])} | {_ms(t['inertia'])} "
            f"| {_ms(t['solve'])} | {'; '.join(notes)} |"
        )

    print("\n## Whole RIPM solves of BandedControlNLP(24, 7, N) (default options)\n")
    print("| N | KKT dim | iterations | total s | ms / iteration | objective |")
    print("|---:|---:|---:|---:|---:|---:|")
    for horizon in [10, 20, 40] if args.quick else [10, 20, 40, 80]:
        dim, iters, wall, obj = ripm_iteration_time(horizon)
        print(
            f"| {horizon} | {dim} | {iters} | {wall:.3f} | {1e3 * wall / max(iters, 1):.2f} "
            f"| {obj:.6g} |"
        )


if __name__ == "__main__":
    main()
