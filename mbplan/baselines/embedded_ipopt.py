"""IPOPT on the embedded (Euclidean) form of problem (11): ``G_i ∈ R^{n×n}`` with ``det G_i = 1``
as equality constraints (the EIPM side of the MLG-IPM paper's §V-C). Problem (10) has no such
form here: ``log`` on SO(n) is not a CasADi primitive.
"""

from __future__ import annotations

import functools
import time

import casadi as cs
import numpy as np

from mbplan.baselines.ipopt import IpoptStats, base_options


# process-wide cache, result-neutral: a CasADi solver of its arguments alone
@functools.lru_cache(maxsize=4)
def _sl_trace_solver(n: int, k: int, c: float, max_iter: int, tol: float) -> cs.Function:
    X = cs.SX.sym("G", n * n * k)
    A = cs.SX.sym("A", n * n)
    Am = cs.reshape(A, n, n)
    Gs = [cs.reshape(X[i * n * n : (i + 1) * n * n], n, n) for i in range(k)]
    t = [cs.trace(cs.mtimes(Am, G)) for G in Gs]
    f = 0.5 * sum(ti**2 for ti in t)
    g = cs.vertcat(*[cs.det(G) - 1.0 for G in Gs], *[c - ti**2 for ti in t])
    opts = {f"ipopt.{k_}": v for k_, v in base_options(max_iter, tol).items()}
    opts |= {"print_time": False, "record_time": True}
    return cs.nlpsol("sl_trace_embedded", "ipopt", {"x": X, "p": A, "f": f, "g": g}, opts)


def solve_sl_trace_ipopt(
    Gd: np.ndarray, G0: np.ndarray, c: float, max_iter: int = 500, tol: float = 1e-8
) -> dict:
    """Solve (11) from ``G0`` (shape (k, n, n)); returns status, iterations, times and the
    final point (projected nowhere: ``det`` is only satisfied to IPOPT's tolerance)."""
    k, n, _ = G0.shape
    solver = _sl_trace_solver(n, k, float(c), int(max_iter), float(tol))
    x0 = np.concatenate([G.ravel(order="F") for G in G0])
    A = np.linalg.inv(Gd).ravel(order="F")
    m_eq = k
    lbg = np.concatenate([np.zeros(m_eq), np.full(k, -np.inf)])
    ubg = np.zeros(2 * k)
    t0 = time.perf_counter()
    sol = solver(x0=x0, p=A, lbg=lbg, ubg=ubg)
    wall = time.perf_counter() - t0
    stats = IpoptStats.of(solver.stats())
    x = np.asarray(sol["x"]).ravel()
    G = np.stack([x[i * n * n : (i + 1) * n * n].reshape(n, n, order="F") for i in range(k)])
    return {
        "status": stats.status,
        "success": bool(solver.stats()["success"]),
        "iterations": stats.iterations,
        "time_s": wall,
        "objective": float(sol["f"]),
        "G": G,
        "det_error": float(np.max(np.abs(np.linalg.det(G) - 1.0))),
    }
