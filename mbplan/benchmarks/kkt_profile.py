"""Inside one RIPM solve: the per-iteration time breakdown and the factorization cost (flops,
fill) of the KKT orderings."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from typing import Any

import numpy as np

from mbplan.engine.callback import CallbackFunction
from mbplan.multibody import coal_pass
from mbplan.solvers import RIPMOptions, RIPMResult, solve_ripm
from mbplan.solvers.kkt import system as ls
from mbplan.solvers.kkt.ldl.symbolic import Analysis
from mbplan.solvers.kkt.ordering import amd_order, coordinate_dissection_order
from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem
from mbplan.workspace import Workspace


class _TimedProblem:
    """The problem with timers around ``evaluate``, ``values`` and ``retract``."""

    def __init__(self, problem: Any, clock: dict[str, float]) -> None:
        self._p, self._clock = problem, clock
        self.n, self.n_eq, self.n_ineq = problem.n, problem.n_eq, problem.n_ineq

    def _timed(self, key: str, fn: Callable, *args: Any, **kw: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kw)
        finally:
            self._clock[key] += time.perf_counter() - t0
            self._clock["n_" + key] += 1

    def evaluate(self, *args: Any, **kw: Any) -> Any:
        return self._timed("evaluate", self._p.evaluate, *args, **kw)

    def values(self, *args: Any, **kw: Any) -> Any:
        return self._timed("values", self._p.values, *args, **kw)

    def retract(self, *args: Any, **kw: Any) -> Any:
        return self._timed("retract", self._p.retract, *args, **kw)

    def __getattr__(self, name: str) -> Any:
        """Everything else (e.g. the ``elimination_plan`` of ``kkt_method="reduced"``) untimed."""
        return getattr(self._p, name)


PROFILE_KEYS = ("evaluate", "values", "retract", "assembly", "factorize", "solve")
DISTANCE_KEYS = ("distances", "coal", "coal_pairs")
"""Inside ``evaluate``/``values``: the coal distance callbacks, the compiled coal pass and the
number of pairs it was asked."""
_KKT_CLASSES = (ls.KKTSystem, ReducedKKTSystem)


@contextmanager
def _timed_kkt(clock: dict[str, float]):
    """Timers on the KKT systems' methods (class-level patches, restored on exit); a call made
    from inside a timed call (the reduced system's own full and reduced systems) is not counted
    again."""
    methods = ("set_matrices", "factorize", "solve")
    saved = {(cls, name): getattr(cls, name) for cls in _KKT_CLASSES for name in methods}
    key = {"set_matrices": "assembly", "factorize": "factorize", "solve": "solve"}
    depth = [0]

    def wrap(cls: type, name: str) -> Callable:
        fn = saved[cls, name]

        def timed(self: Any, *args: Any, **kw: Any) -> Any:
            depth[0] += 1
            t0 = time.perf_counter()
            try:
                return fn(self, *args, **kw)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    clock[key[name]] += time.perf_counter() - t0
                    clock["n_" + key[name]] += 1

        return timed

    try:
        for cls, name in saved:
            setattr(cls, name, wrap(cls, name))
        yield
    finally:
        for (cls, name), fn in saved.items():
            setattr(cls, name, fn)


@contextmanager
def _timed_distances(clock: dict[str, float]):
    """Timers on the coal distance callbacks (inside ``evaluate`` and ``values``: not part of
    the profile's sum) and on the compiled coal pass, with the pairs it was asked."""
    call, sites = CallbackFunction._call, coal_pass.site_distances

    def timed_call(self: CallbackFunction, kind: str, inputs: list) -> list:
        t0 = time.perf_counter()
        try:
            return call(self, kind, inputs)
        finally:
            clock["distances"] += time.perf_counter() - t0

    def timed_sites(*args: Any) -> Any:
        t0 = time.perf_counter()
        found = sites(*args)
        clock["coal"] += time.perf_counter() - t0
        clock["coal_pairs"] += 0 if found is None else found[3]
        return found

    try:
        CallbackFunction._call, coal_pass.site_distances = timed_call, timed_sites
        yield
    finally:
        CallbackFunction._call, coal_pass.site_distances = call, sites


def warm_kkt(problem: Any, x0: Any, seed: int = 0) -> tuple[tuple, np.ndarray, np.ndarray]:
    """A KKT system of ``problem`` at ``x0`` as the RIPM meets it: multipliers ``y ~ N(0, 1)``,
    ``z, s`` uniform in ``[0.5, 2]``, ``δ_w = 1e-6``; its blocks (Hessian's lower triangle,
    ``A_E``, ``A_I``), diagonal and a random right-hand side."""
    rng = np.random.default_rng(seed)
    z, s = rng.uniform(0.5, 2.0, (2, problem.n_ineq))
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    blocks = (ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    diag = np.concatenate([np.full(problem.n, 1e-6), np.zeros(problem.n_eq), -s / z])
    return blocks, diag, rng.normal(size=problem.n + problem.n_eq + problem.n_ineq)


def profile_solve(problem: Any, x0: Any, options: RIPMOptions) -> dict[str, Any]:
    """Solve once (after a warm-up solve for compilation and the symbolic work, kept in a
    workspace both solves share) and return the time per iteration of each part, in ms, with
    counts per iteration; with coal distances also their time per iteration, their share of
    the solve and the compiled pass's pairs per iteration and µs per pair."""
    workspace = Workspace()
    solve_ripm(problem, x0, options, workspace=workspace)
    clock: dict[str, float] = dict.fromkeys(PROFILE_KEYS, 0.0)
    clock |= {"n_" + k: 0 for k in PROFILE_KEYS} | dict.fromkeys(DISTANCE_KEYS, 0.0)
    with _timed_kkt(clock), _timed_distances(clock):
        t0 = time.perf_counter()
        res: RIPMResult = solve_ripm(
            _TimedProblem(problem, clock), x0, options, workspace=workspace
        )
        wall = time.perf_counter() - t0
    it = max(res.iterations, 1)
    parts = sum(clock[k] for k in PROFILE_KEYS)
    row: dict[str, Any] = {
        "status": res.status.name,
        "iterations": res.iterations,
        "restoration_iterations": int(np.sum(res.history.restoration)),
        "total_ms": 1e3 * wall,
        "per_iter_ms": 1e3 * wall / it,
    }
    for k in PROFILE_KEYS:
        row[k + "_ms"] = 1e3 * clock[k] / it
    row["python_ms"] = 1e3 * (wall - parts) / it
    for k in PROFILE_KEYS:
        row[k + "_per_iter"] = clock["n_" + k] / it
    row["kkt_dim"] = problem.n + problem.n_eq + problem.n_ineq
    if clock["distances"]:
        row["distances_ms"] = 1e3 * clock["distances"] / it
        row["distance_share"] = clock["distances"] / wall
        row["coal_pairs_per_iter"] = clock["coal_pairs"] / it
        row["us_per_coal_pair"] = 1e6 * clock["coal"] / max(clock["coal_pairs"], 1)
    return row


# ------------------------------------------------------------------------------- orderings


def _grid_keys(problem: Any, ev: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(knot, body) of every KKT unknown of a TrajectoryProblem: primal coordinates from their
    block (``flat = knot * count + element``), constraint rows from the first of their columns."""
    variables = getattr(problem, "variables", None)
    if variables is None:
        return None
    knot, body = np.zeros(problem.n, np.int64), np.zeros(problem.n, np.int64)
    for name, b in variables.blocks.items():
        idx = variables.tangent_index(name)
        flat = np.repeat(np.arange(idx.shape[0]), idx.shape[1]).reshape(idx.shape)
        free = idx >= 0
        knot[idx[free]] = flat[free] // b.count
        body[idx[free]] = flat[free] % b.count
    keys = [knot, body]
    for jac in (ev.eq_jacobian, ev.ineq_jacobian):
        jac = jac.tocsr()
        rows = np.repeat(np.arange(jac.shape[0]), np.diff(jac.indptr))
        for i, key in enumerate((knot, body)):
            empty = np.iinfo(np.int64).max
            first = np.full(jac.shape[0], empty)
            np.minimum.at(first, rows, key[jac.indices])
            keys[i] = np.concatenate([keys[i], np.where(first == empty, 0, first)])
    return keys[0], keys[1]


def ordering_stats(problem: Any, x0: Any) -> dict[str, dict[str, float]]:
    """Predicted flops (multiply-adds) and stored factor entries of the KKT matrix at ``x0`` for
    each elimination order: AMD, METIS and BFS nested dissection (:mod:`mbplan.solvers.kkt.ordering`)
    and, for a
    trajectory problem, AMD constrained to eliminate knot by knot (time-major, stage-wise) or
    body by body (body-major)."""
    ev = problem.evaluate(x0, 1.0, np.zeros(problem.n_eq), np.ones(problem.n_ineq))
    out = {}
    for ordering in ("amd", "metis", "nested"):
        kkt = ls.KKTSystem(problem.n, problem.n_eq, problem.n_ineq, ordering=ordering)
        kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
        a = kkt.analysis
        out[ordering] = {"flops": a.flops, "nnz_factor": a.nnz_factor, "kkt_dim": kkt.dim}
    keys = _grid_keys(problem, ev)
    if keys is not None:
        amd, indptr, indices = kkt_amd_perm(problem, ev)
        rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        for name, (major, minor) in (("time-major", keys), ("body-major", keys[::-1])):
            perm = amd[np.lexsort((minor[amd], major[amd]))]
            a = Analysis(len(indptr) - 1, rows, indices, perm)
            out[name] = {"flops": a.flops, "nnz_factor": a.nnz_factor, "kkt_dim": len(perm)}
        dense = stage_dense_cost(keys[0], indptr, indices)
        if dense is not None:
            out["stage-dense"] = {**dense, "kkt_dim": len(amd)}
        coords = np.column_stack(keys).astype(float)
        perm = coordinate_dissection_order(indptr, indices, coords)
        a = Analysis(len(indptr) - 1, rows, indices, perm)
        out["grid-nd"] = {"flops": a.flops, "nnz_factor": a.nnz_factor, "kkt_dim": len(perm)}
    return out


def stage_dense_cost(
    knot: np.ndarray, indptr: np.ndarray, indices: np.ndarray
) -> dict[str, float] | None:
    """Multiply-adds and stored entries of a block-tridiagonal LDLᵀ with dense knot blocks (a
    Riccati-like stage-wise recursion: factor knot k's block, ``b³/6``; solve its coupling to
    the ``c`` unknowns of knot k+1 it touches, ``c b²/2``; update their Schur complement,
    ``c² b/2``); ``None`` unless every entry couples a knot only to itself or its neighbour."""
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    ki, kj = knot[rows], knot[indices]
    if np.any(np.abs(ki - kj) > 1):
        return None
    knots = int(knot.max()) + 1
    b = np.bincount(knot, minlength=knots).astype(float)
    cross = ki != kj
    later = np.where(ki > kj, rows, indices)[cross]  # the unknown of the later knot
    c = np.bincount(knot[np.unique(later)], minlength=knots).astype(float)
    c = np.concatenate([c[1:], [0.0]])  # knot k's coupling into knot k + 1
    flops = float(np.sum(b**3 / 6 + c * b**2 / 2 + c**2 * b / 2))
    return {"flops": flops, "nnz_factor": float(np.sum(b * (b + 1) / 2 + c * b))}


def kkt_amd_perm(problem: Any, ev: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The AMD order of the KKT pattern at ``ev`` and the pattern (lower CSR arrays)."""
    kkt = ls.KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    return amd_order(kkt._indptr, kkt._indices), kkt._indptr, kkt._indices
