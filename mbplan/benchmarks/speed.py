"""Speed of the RIPM against the baselines on its own tasks, with a per-iteration profile.

Task construction is one small function per task (:func:`iiwa_task`, :func:`drone_task`,
:func:`chain_task`) so that it can move onto another task API without touching the rest.
"""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.solvers import RIPMOptions, RIPMResult, solve_ripm
from mbplan.solvers import linear_solver as ls
from mbplan.solvers.ordering import amd_order, coordinate_dissection_order

# ------------------------------------------------------------------------------- tasks


def iiwa_task(index: int, n: int = 100, seed: int = 0, constraint: str = "com"):
    """iiwa obstacle case ``index`` of ``n`` (N = 40) as an OCP (:mod:`mbplan.paper`)."""
    from mbplan.paper import iiwa_obstacle, iiwa_obstacle_starts

    q0 = iiwa_obstacle_starts(n, seed, constraint)[index]
    return iiwa_obstacle(q0, N=40, constraint=constraint)


def maximal_ripm_problem(ocp, warm_start: str = "via") -> tuple[Any, Any]:
    """The RIPM's problem and warm start for an OCP (as ``plan(ocp, "ripm")`` builds them)."""
    from mbplan.engine.jit import jit_available
    from mbplan.formulations import maximal
    from mbplan.planning.initial_guess import initial_path

    nlp, _ = maximal.build(ocp, jit_available())
    return nlp.problem, nlp.initial_point(initial_path(ocp, warm_start))


def drone_task(index: int, n: int = 100, seed: int = 0, limits: bool = False):
    """Drone docking case ``index`` of ``n`` (RIPM paper §VIII.B)."""
    from mbplan.tasks.drone import sample_docking_cases

    return sample_docking_cases(n, seed, with_input_limits=limits)[index]


def drone_ripm_problem(task) -> tuple[Any, Any]:
    from mbplan.tasks.drone import geodesic_initial_guess
    from mbplan.transcription.quadrotor import quadrotor_problem

    problem = quadrotor_problem(task)
    return problem, problem.check_point(geodesic_initial_guess(task))


CHAIN_LINKS = (4, 8, 16, 32, 64)
CHAIN_LENGTH = 1.0  # m, whole chain
CHAIN_MASS = 2.0  # kg, whole chain


def chain_urdf(n: int) -> str:
    """URDF of a hanging serial chain of ``n`` equal links (revolute x, y, x, ...), 1 m, 2 kg."""
    L, m, r = CHAIN_LENGTH / n, CHAIN_MASS / n, 0.01
    ixx, izz = m * (3 * r * r + L * L) / 12, m * r * r / 2
    parts = ['<?xml version="1.0"?>', f'<robot name="chain{n}">', '<link name="base"/>']
    parent = "base"
    for i in range(n):
        link = f"link{i + 1}"
        parts.append(
            f'<link name="{link}"><inertial><origin xyz="0 0 {-L / 2}"/><mass value="{m}"/>'
            f'<inertia ixx="{ixx}" iyy="{ixx}" izz="{izz}" ixy="0" ixz="0" iyz="0"/>'
            "</inertial></link>"
        )
        axis = "1 0 0" if i % 2 == 0 else "0 1 0"
        z = -L if i else 0.0
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{link}"/><origin xyz="0 0 {z}"/><axis xyz="{axis}"/>'
            '<limit lower="-3.1" upper="3.1" effort="100" velocity="10"/></joint>'
        )
        parent = link
    parts.append("</robot>")
    return "\n".join(parts)


@functools.cache
def _chain_path(n: int) -> str:
    path = Path(tempfile.gettempdir()) / f"mbplan-chain{n}.urdf"
    text = chain_urdf(n)
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(f".{time.time_ns()}.tmp")
        tmp.write_text(text)
        tmp.replace(path)
    return str(path)


def chain_task(n: int, N: int = 40):
    """Reach with an ``n``-link hanging chain: from rest at q = 0 to a curl of 1.2 rad total."""
    from mbplan.paper import tracking_ocp

    return tracking_ocp(_chain_path(n), np.zeros(n), np.full(n, 1.2 / n), N=N)


def _iiwa(i: int):
    return (*maximal_ripm_problem(iiwa_task(i)), RIPMOptions(tol=1e-6, max_iter=500))


def _drone(i: int, limits: bool = False):
    return (*drone_ripm_problem(drone_task(i, limits=limits)), RIPMOptions(tol=1e-6, max_iter=100))


def _chain(n: int):
    return (*maximal_ripm_problem(chain_task(n), "linear"), RIPMOptions(tol=1e-6, max_iter=500))


TASKS: dict[str, Callable[[int], tuple]] = {
    "iiwa-com": _iiwa,
    "drone": _drone,
    "drone-limits": functools.partial(_drone, limits=True),
    **{f"chain{n}": (lambda _i, n=n: _chain(n)) for n in CHAIN_LINKS},
}

# ------------------------------------------------------------------------------- profile


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


PROFILE_KEYS = ("evaluate", "values", "retract", "assembly", "factorize", "solve")


@contextmanager
def _timed_kkt(clock: dict[str, float]):
    """Timers on the KKT system's methods (class-level patch, restored on exit)."""
    cls = ls.KKTSystem
    saved = {name: getattr(cls, name) for name in ("set_matrices", "factorize", "solve")}
    key = {"set_matrices": "assembly", "factorize": "factorize", "solve": "solve"}

    def wrap(name: str) -> Callable:
        fn = saved[name]

        def timed(self: Any, *args: Any, **kw: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(self, *args, **kw)
            finally:
                clock[key[name]] += time.perf_counter() - t0
                clock["n_" + key[name]] += 1

        return timed

    try:
        for name in saved:
            setattr(cls, name, wrap(name))
        yield
    finally:
        for name, fn in saved.items():
            setattr(cls, name, fn)


def profile_solve(problem: Any, x0: Any, options: RIPMOptions) -> dict[str, Any]:
    """Solve once (after a warm-up solve for compilation and pattern analysis) and return the
    time per iteration of each part, in ms, with counts per iteration."""
    solve_ripm(problem, x0, options)
    clock: dict[str, float] = dict.fromkeys(PROFILE_KEYS, 0.0)
    clock |= {"n_" + k: 0 for k in PROFILE_KEYS}
    with _timed_kkt(clock):
        t0 = time.perf_counter()
        res: RIPMResult = solve_ripm(_TimedProblem(problem, clock), x0, options)
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
    return row


def chain_case(method: str, links: int) -> dict:
    """One chain reach solve (``ripm`` or ``ipopt``) with its verification, as a JSON row."""
    from mbplan.planning.solve import plan
    from mbplan.verification import verify

    ocp = chain_task(links)
    t0 = time.perf_counter()
    plan(ocp, method, warm_start="linear")  # cold: compilation, symbolic analysis
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = plan(ocp, method, warm_start="linear", tol=1e-6, max_iter=500)
    wall = time.perf_counter() - t0
    check = verify(ocp, result)
    return {
        "cold_total_time_s": cold,
        "success": bool(result.success),
        "status": result.status,
        "iterations": int(result.iterations),
        "solve_time_s": float(result.solve_time_s),
        "total_time_s": float(wall),
        "time_per_iter_s": float(result.time_per_iter_s),
        "verified": bool(check.passed),
        "verification_reasons": check.reasons,
    }


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
            first = np.full(jac.shape[0], np.iinfo(np.int64).max)
            np.minimum.at(first, rows, key[jac.indices])
            keys[i] = np.concatenate([keys[i], np.where(first == first.max(initial=0), 0, first)])
    return keys[0], keys[1]


def ordering_stats(problem: Any, x0: Any) -> dict[str, dict[str, float]]:
    """Predicted flops (multiply-adds) and stored factor entries of the KKT matrix at ``x0`` for
    each elimination order: AMD, nested dissection (:mod:`mbplan.solvers.ordering`) and, for a
    trajectory problem, AMD constrained to eliminate knot by knot (time-major, stage-wise) or
    body by body (body-major)."""
    ev = problem.evaluate(x0, 1.0, np.zeros(problem.n_eq), np.ones(problem.n_ineq))
    out = {}
    for ordering in ("amd", "nested"):
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
            a = ls._Analysis(len(indptr) - 1, rows, indices, perm)
            out[name] = {"flops": a.flops, "nnz_factor": a.nnz_factor, "kkt_dim": len(perm)}
        coords = np.column_stack(keys).astype(float)
        perm = coordinate_dissection_order(indptr, indices, coords)
        a = ls._Analysis(len(indptr) - 1, rows, indices, perm)
        out["grid-nd"] = {"flops": a.flops, "nnz_factor": a.nnz_factor, "kkt_dim": len(perm)}
    return out


def kkt_amd_perm(problem: Any, ev: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The AMD order of the KKT pattern at ``ev`` and the pattern (lower CSR arrays)."""
    kkt = ls.KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    return amd_order(kkt._indptr, kkt._indices), kkt._indptr, kkt._indices


# ------------------------------------------------------------------------------- benchmark

IIWA_METHODS = ("ripm", "ipopt", "csqp")
DRONE_METHODS = ("ripm", "ripm-input-limits", "ipopt-quaternion")
CHAIN_METHODS = ("ripm", "ipopt")


def _med(rows: list[dict], key: str, ok_only: bool = True) -> float | None:
    vals = [r[key] for r in rows if (r["success"] or not ok_only) and r.get(key) is not None]
    return float(np.median(vals)) if vals else None


def _method_stats(rows: list[dict]) -> dict[str, Any]:
    return {
        "n": len(rows),
        "converged": sum(r["success"] for r in rows),
        "verified": sum(bool(r.get("verified", r["success"])) and r["success"] for r in rows),
        "median_iters": _med(rows, "iterations"),
        "median_time_per_iter_s": _med(rows, "time_per_iter_s"),
        "median_total_time_s": _med(rows, "total_time_s") or _med(rows, "solve_time_s"),
        "statuses": {s: sum(r["status"] == s for r in rows) for s in {r["status"] for r in rows}},
    }


def run(
    out: Path,
    n_iiwa: int = 100,
    n_drone: int = 100,
    links: tuple[int, ...] = CHAIN_LINKS,
    seed: int = 0,
    workers: int = 1,
    scheduler: str | None = None,
    profile_cases: int = 3,
) -> dict:
    """Every method side by side on the drone, the iiwa (com, via warm start) and the chain
    reach; then the RIPM's per-iteration profile and the orderings' flops. Writes
    results.jsonl files (resumable), summary.json, results.md and plots under ``out``."""
    from mbplan.benchmarks import drone_docking, iiwa_obstacle
    from mbplan.benchmarks.common import machine_info, write_atomic, write_json
    from mbplan.benchmarks.harness import Job, run_jobs

    out.mkdir(parents=True, exist_ok=True)
    pool = {"workers": workers, "scheduler": scheduler}
    summary: dict[str, Any] = {"tasks": {}}
    sections = (
        (
            "iiwa-com",
            n_iiwa,
            [
                Job(i, m, iiwa_obstacle.solve_case, (m, n_iiwa, seed, i, 40, 1e-6, 500, "via"))
                for i in range(n_iiwa)
                for m in IIWA_METHODS
            ],
        ),
        (
            "drone",
            n_drone,
            [
                Job(i, m, drone_docking.solve_case, (m, n_drone, seed, i, 1e-6))
                for i in range(n_drone)
                for m in DRONE_METHODS
            ],
        ),
        (
            "chain",
            len(links),
            [Job(k, m, chain_case, (m, k)) for k in links for m in CHAIN_METHODS],
        ),
    )
    rows_by_task = {}
    for name, count, jobs in sections:
        if not count:
            continue
        config = {"benchmark": f"speed-{name}", "seed": seed, "tol": 1e-6, "N": 40}
        rows = run_jobs(jobs, out / f"{name}.jsonl", config=config, description=name, **pool)
        keys = {j.key for j in jobs}
        rows = [r for r in rows if (r["case"], r["method"]) in keys]
        rows_by_task[name] = rows
        methods = sorted({r["method"] for r in rows})
        if name == "chain":
            summary["tasks"][name] = {
                m: {
                    str(k): _method_stats([r for r in rows if r["method"] == m and r["case"] == k])
                    for k in links
                }
                for m in methods
            }
        else:
            summary["tasks"][name] = {
                m: _method_stats([r for r in rows if r["method"] == m]) for m in methods
            }
    profile: dict[str, list[dict]] = {}
    names = ["iiwa-com"] * bool(n_iiwa) + ["drone", "drone-limits"] * bool(n_drone)
    for name in names:
        profile[name] = [profile_solve(*TASKS[name](i)) for i in range(profile_cases)]
    for k in links:
        profile[f"chain{k}"] = [profile_solve(*_chain(k))]
    summary["profile"] = {
        name: {key: float(np.median([r[key] for r in rs])) for key in rs[0] if key != "status"}
        for name, rs in profile.items()
    }
    orderings = {}
    if n_iiwa:
        orderings["iiwa-com"] = ordering_stats(*maximal_ripm_problem(iiwa_task(0)))
    if n_drone:
        orderings["drone"] = ordering_stats(*drone_ripm_problem(drone_task(0)))
    for k in links:
        orderings[f"chain{k}"] = ordering_stats(*maximal_ripm_problem(chain_task(k), "linear"))
    summary["orderings"] = orderings
    if n_drone:
        summary["drone_horizon_scaling"] = drone_docking.horizon_scaling(seed)
    summary["command"] = (
        f"mbplan bench speed --n-iiwa {n_iiwa} --n-drone {n_drone} "
        f"--links {','.join(map(str, links))} --seed {seed} --workers {workers} --out {out}"
    )
    summary["machine"] = machine_info()
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    if "chain" in rows_by_task:
        _chain_plot(summary, links, out)
    return summary


def _ratio(a: float | None, b: float | None) -> str:
    return "—" if a is None or b is None or b == 0 else f"{a / b:.2f}"


def _fmt(v: float | None, scale: float = 1.0, digits: int = 1) -> str:
    return "—" if v is None else f"{scale * v:.{digits}f}"


_ORDERS = ("amd", "nested", "grid-nd", "time-major", "body-major")


def _markdown(s: dict) -> str:
    lines = [
        "# Speed: the RIPM against the baselines on its own tasks",
        "",
        f"Command: `{s['command']}`  ",
        "Every method in one run, on the same (shared, 2-core) machine: only ratios mean "
        "anything. Time per iteration and total time are medians over converged runs.",
        "",
    ]
    for task in ("iiwa-com", "drone"):
        if task not in s["tasks"]:
            continue
        ms = s["tasks"][task]
        base = "ipopt" if task == "iiwa-com" else "ipopt-quaternion"
        lines += [
            f"## {task}",
            "",
            "| method | solved & verified | converged | median iters | time/iter [ms] "
            f"| total [ms] | total / {base} | time/iter / {base} |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        b = ms.get(base, {})
        for name, m in ms.items():
            lines.append(
                f"| {name} | {m['verified']}/{m['n']} | {m['converged']}/{m['n']} "
                f"| {_fmt(m['median_iters'])} | {_fmt(m['median_time_per_iter_s'], 1e3, 2)} "
                f"| {_fmt(m['median_total_time_s'], 1e3)} "
                f"| {_ratio(m['median_total_time_s'], b.get('median_total_time_s'))} "
                f"| {_ratio(m['median_time_per_iter_s'], b.get('median_time_per_iter_s'))} |"
            )
        lines += ["", "Statuses: " + "; ".join(f"{n}: {m['statuses']}" for n, m in ms.items()), ""]
    if "chain" in s["tasks"]:
        ch = s["tasks"]["chain"]
        links = list(next(iter(ch.values())))
        lines += [
            "## Chain reach (N = 40, no obstacles), RIPM vs generalized IPOPT",
            "",
            "Warm solves (a cold solve with compilation and symbolic analysis runs first).",
            "",
            "| links | RIPM iters | RIPM ms/iter | IPOPT iters | IPOPT ms/iter | RIPM total [s] "
            "| IPOPT total [s] | total RIPM/IPOPT | verified RIPM / IPOPT |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for k in links:
            r, i = ch["ripm"][k], ch["ipopt"][k]
            lines.append(
                f"| {k} | {_fmt(r['median_iters'], digits=0)} "
                f"| {_fmt(r['median_time_per_iter_s'], 1e3)} | {_fmt(i['median_iters'], digits=0)} "
                f"| {_fmt(i['median_time_per_iter_s'], 1e3)} | {_fmt(r['median_total_time_s'], digits=2)} "
                f"| {_fmt(i['median_total_time_s'], digits=2)} "
                f"| {_ratio(r['median_total_time_s'], i['median_total_time_s'])} "
                f"| {r['verified']} / {i['verified']} |"
            )
        lines.append("")
    prof = s["profile"]
    lines += [
        "## RIPM profile per iteration (median over the profiled cases, ms per iteration)",
        "",
        "`evaluate`: derivatives at the iterate; `values`/`retract`: line-search trials; "
        "`assembly`: KKT values into the fixed pattern; `factorize`: numeric LDLᵀ (all inertia "
        "trials); `solve`: triangular solves with refinement; `python`: the rest.",
        "",
        "| task | KKT dim | iters | ms/iter | evaluate | values | retract | assembly | factorize "
        "| solve | python | factorizations/iter | solves/iter | trials/iter |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, p in prof.items():
        lines.append(
            f"| {name} | {p['kkt_dim']:.0f} | {p['iterations']:.0f} | {p['per_iter_ms']:.2f} "
            + " ".join(
                f"| {p[k + '_ms']:.2f}"
                for k in (
                    "evaluate",
                    "values",
                    "retract",
                    "assembly",
                    "factorize",
                    "solve",
                    "python",
                )
            )
            + f" | {p['factorize_per_iter']:.2f} | {p['solve_per_iter']:.2f} "
            f"| {p['values_per_iter']:.2f} |"
        )
    lines += [
        "",
        "## Elimination orders: predicted factorization cost",
        "",
        "Mflop = multiply-adds of the numeric LDLᵀ (supernodal, relaxed amalgamation), fill = "
        "stored factor entries (millions). nested: dissection by BFS levels of the graph; grid-nd: "
        "dissection of the time × body grid by coordinates; time-/body-major: AMD's order made to eliminate the "
        "time × body grid knot by knot (a stage-wise, Riccati-like elimination) or body by body.",
        "",
        "| task | KKT dim | "
        + " | ".join(f"{o} Mflop / fill" for o in _ORDERS)
        + " | fewest flops |",
        "|---|---:|" + "---:|" * len(_ORDERS) + "---|",
    ]
    for name, o in s["orderings"].items():
        cells = [
            f"{o[k]['flops'] / 1e6:.1f} / {o[k]['nnz_factor'] / 1e6:.2f}" if k in o else "—"
            for k in _ORDERS
        ]
        best = min((k for k in _ORDERS if k in o), key=lambda k: o[k]["flops"])
        lines.append(f"| {name} | {o['amd']['kkt_dim']} | " + " | ".join(cells) + f" | {best} |")
    if "drone_horizon_scaling" in s:
        h = s["drone_horizon_scaling"]
        lines += [
            "",
            f"Drone, whole iteration N = 160 / N = 40: {h['ratio']:.2f} (linear: "
            f"{h['linear_ratio']:.0f}).",
        ]
    return "\n".join(lines) + "\n"


def _chain_plot(s: dict, links: tuple[int, ...], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mbplan.benchmarks.common import save_plot

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    ch = s["tasks"]["chain"]
    x = np.array(links, dtype=float)
    for m, style in (("ripm", "o-"), ("ipopt", "s-")):
        per = [ch[m][str(k)]["median_time_per_iter_s"] for k in links]
        tot = [ch[m][str(k)]["median_total_time_s"] for k in links]
        axes[0].loglog(x, [np.nan if v is None else v for v in per], style, label=m)
        axes[1].loglog(x, [np.nan if v is None else v for v in tot], style, label=m)
    for ax, what in zip(axes, ("time per iteration [s]", "total time [s]"), strict=True):
        ref = ax.get_lines()[0].get_ydata()[0]
        if np.isfinite(ref):
            ax.loglog(x, ref * (x / x[0]) ** 1.5, "k:", lw=0.8, label="∝ n^1.5")
        ax.set_xlabel("links")
        ax.set_ylabel(what)
        ax.legend()
    fig.suptitle("Chain reach, N = 40: maximal (RIPM) vs generalized (IPOPT)")
    fig.tight_layout()
    save_plot(fig, out / "chain_scaling.png", dpi=110)
