"""Speed of the RIPM against the baselines on its own tasks, with a per-iteration profile.

Tasks: :mod:`mbplan.tasks.speed`; profile and orderings:
:mod:`mbplan.benchmarks.kkt_profile`.
"""

from __future__ import annotations

import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.benchmarks.common import plan_row
from mbplan.benchmarks.kkt_profile import ordering_stats, profile_solve
from mbplan.planning.solve import plan
from mbplan.tasks.speed import (
    CHAIN_LINKS,
    TASKS,
    chain_problem,
    chain_task,
    drone_task,
    iiwa_task,
    maximal_ripm_problem,
)
from mbplan.workspace import Workspace

# ------------------------------------------------------------------------------- benchmark

IIWA_METHODS = ("ripm", "ipopt", "csqp")
IIWA_DISTANCE_METHODS = ("ripm", "ipopt")  # CSQP's Python coal residual: 10–30 s per solve
DRONE_METHODS = ("ripm", "ripm-input-limits", "ipopt-quaternion")
CHAIN_METHODS = ("ripm", "ipopt")


def _med(rows: list[dict], key: str, ok_only: bool = True) -> float | None:
    vals = [r[key] for r in rows if (r["success"] or not ok_only) and r.get(key) is not None]
    return float(np.median(vals)) if vals else None


def _baseline(task: str) -> str:
    """The method every other one of a task is compared with."""
    return "ipopt" if task.startswith("iiwa") else "ipopt-quaternion"


def _by_case(rows: list[dict], key: str) -> dict[Any, float | None]:
    """``key`` of one method's rows by case, ``None`` where it did not converge (as :func:`_med`)."""
    return {r["case"]: r.get(key) if r["success"] else None for r in rows}


INTERVALS = {
    "kind": "paired percentile bootstrap over the cases",
    "level": 0.95,
    "draws": 2000,
    "seed": 0,
}
"""How :func:`_intervals` draws (stored in summary.json and named in results.md)."""


def _total_key(rows: list[dict]) -> str:
    """The key of a method's *total* time: its total, or its solve time where it has none
    (as :func:`_method_stats`)."""
    return "total_time_s" if _med(rows, "total_time_s") else "solve_time_s"


def _intervals(rows: list[dict], base: str) -> dict[str, dict[str, tuple[float, float] | None]]:
    """:data:`INTERVALS` (:func:`~mbplan.benchmarks.common.median_ratio_interval`) of each
    method's median time per iteration and of its medians' ratios to ``base``'s."""
    from mbplan.benchmarks.common import median_ratio_interval

    draw = {k: INTERVALS[k] for k in ("level", "draws", "seed")}
    of = {m: [r for r in rows if r["method"] == m] for m in sorted({r["method"] for r in rows})}
    out = {}
    for m, own in of.items():
        out[m] = {
            "time_per_iter_s": median_ratio_interval(_by_case(own, "time_per_iter_s"), **draw)
        }
        if m == base or base not in of:
            continue
        keys = {
            "total": (_total_key(own), _total_key(of[base])),
            "solve": ("solve_time_s", "solve_time_s"),
            "time_per_iter": ("time_per_iter_s", "time_per_iter_s"),
        }
        for name, (mine, theirs) in keys.items():
            out[m][f"{name}_ratio"] = median_ratio_interval(
                _by_case(own, mine), _by_case(of[base], theirs), **draw
            )
    return out


def _method_stats(rows: list[dict]) -> dict[str, Any]:
    return {
        "n": len(rows),
        "converged": sum(r["success"] for r in rows),
        "verified": sum(bool(r.get("verified", r["success"])) and r["success"] for r in rows),
        "median_iters": _med(rows, "iterations"),
        "median_time_per_iter_s": _med(rows, "time_per_iter_s"),
        "median_total_time_s": _med(rows, "total_time_s") or _med(rows, "solve_time_s"),
        "median_solve_time_s": _med(rows, "solve_time_s"),
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
    n_iiwa_distance: int | None = None,
) -> dict:
    """Every method side by side on the drone, the iiwa (via warm start; eq. 62 ``com`` and
    coal ``distance`` constraints, ``n_iiwa_distance`` cases, default ``n_iiwa``) and the chain
    reach without and with an obstacle; then the RIPM's per-iteration profile and the
    orderings' flops. Writes results.jsonl files (resumable), summary.json, results.md and
    plots under ``out``."""
    from mbplan.benchmarks import drone_docking, iiwa_obstacle
    from mbplan.benchmarks.common import machine_info, write_atomic, write_json
    from mbplan.benchmarks.harness import Job, run_jobs

    out.mkdir(parents=True, exist_ok=True)
    n_dist = n_iiwa if n_iiwa_distance is None else n_iiwa_distance
    pool = {"workers": workers, "scheduler": scheduler}
    summary: dict[str, Any] = {"tasks": {}, "intervals": {}, "interval_method": INTERVALS}
    shared = defaultdict(Workspace)  # one per task family and method: its cases share it
    sections = (
        (
            "iiwa-com",
            n_iiwa,
            [
                Job(
                    i,
                    m,
                    iiwa_obstacle.solve_case,
                    (m, n_iiwa, seed, i, 40, 1e-6, 500, "via", "com", shared[("iiwa-com", m)]),
                )
                for i in range(n_iiwa)
                for m in IIWA_METHODS
            ],
        ),
        (
            "iiwa-distance",
            n_dist,
            [
                Job(
                    i,
                    m,
                    iiwa_obstacle.solve_case,
                    (m, n_dist, seed, i, 40, 1e-6, 500, "via", "distance", shared[("dist", m)]),
                )
                for i in range(n_dist)
                for m in IIWA_DISTANCE_METHODS
            ],
        ),
        (
            "drone",
            n_drone,
            [
                Job(
                    i,
                    m,
                    drone_docking.solve_case,
                    (m, n_drone, seed, i, 1e-6, shared[("drone", m)]),
                )
                for i in range(n_drone)
                for m in DRONE_METHODS
            ],
        ),
        (
            "chain",
            len(links),
            [Job(k, m, chain_case, (m, k)) for k in links for m in CHAIN_METHODS],
        ),
        (
            "chain-obstacle",
            len(links),
            [Job(k, m, chain_case, (m, k, True)) for k in links for m in CHAIN_METHODS],
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
        if name.startswith("chain"):
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
            summary["intervals"][name] = _intervals(rows, _baseline(name))
    profile: dict[str, list[dict]] = {}
    names = ["iiwa-com"] * bool(n_iiwa) + ["iiwa-distance"] * bool(n_dist)
    names += ["drone", "drone-limits"] * bool(n_drone)
    for name in names:
        profile[name] = [profile_solve(*TASKS[name](i)) for i in range(profile_cases)]
    for obstacle in (False, True):
        for k in links:
            name = f"chain{k}" + "-obstacle" * obstacle
            profile[name] = [profile_solve(*chain_problem(k, obstacle))]
    summary["profile"] = {
        name: {key: float(np.median([r[key] for r in rs])) for key in rs[0] if key != "status"}
        for name, rs in profile.items()
    }
    orderings = {}
    if n_iiwa:
        orderings["iiwa-com"] = ordering_stats(*maximal_ripm_problem(iiwa_task(0)))
    if n_drone:
        orderings["drone"] = ordering_stats(*maximal_ripm_problem(drone_task(0)))
    for k in links:
        orderings[f"chain{k}"] = ordering_stats(*maximal_ripm_problem(chain_task(k), "linear"))
    summary["orderings"] = orderings
    if n_drone:
        summary["drone_horizon_scaling"] = drone_docking.horizon_scaling(seed)
    summary["command"] = (
        f"mbplan bench speed --n-iiwa {n_iiwa} --n-iiwa-distance {n_dist} --n-drone {n_drone} "
        f"--links {','.join(map(str, links))} --seed {seed} --workers {workers} --out {out}"
    )
    summary["machine"] = machine_info()
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    if {"chain", "chain-obstacle"} & set(rows_by_task):
        _chain_plot(summary, links, out)
    return summary


def _ratio(a: float | None, b: float | None) -> str:
    return _within(_quotient(a, b), None)


def _fmt(v: float | None, scale: float = 1.0, digits: int = 1) -> str:
    return "—" if v is None else f"{scale * v:.{digits}f}"


def _within(value: float | None, interval: tuple[float, float] | None, scale: float = 1.0) -> str:
    """A cell's value with three significant digits and its interval rounded outwards at the
    same decimals, e.g. ``0.262 (0.246–0.273)``; the plain two-decimal value without one."""
    if value is None:
        return "—"
    if interval is None:
        return f"{scale * value:.2f}"
    v, lo, hi = (scale * x for x in (value, *interval))
    d = max(0, 2 - int(np.floor(np.log10(max(abs(v), 1e-300)))))
    f = 10.0**d
    return f"{v:.{d}f} ({np.floor(lo * f) / f:.{d}f}–{np.ceil(hi * f) / f:.{d}f})"


def _quotient(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else a / b


_ORDERS = ("amd", "metis", "nested", "grid-nd", "time-major", "stage-dense", "body-major")


def _markdown(s: dict) -> str:
    lines = [
        "# Speed: the RIPM against the baselines on its own tasks",
        "",
        f"Command: `{s['command']}`  ",
        "Every method in one run, on the same (shared, 2-core) machine: only ratios mean "
        "anything. Time per iteration and total time are medians over converged runs. "
        "*total* is the wall time of `mbplan.plan` (building the formulation, warm start, solve, "
        "result), *solve* the solver's own time: the quaternion IPOPT builds its CasADi NLP "
        "anew for every case, the maximal formulation reuses its compiled terms, so compare "
        "the solvers by *solve*.",
        "",
    ]
    if s.get("intervals"):
        i = s.get("interval_method", INTERVALS)
        lines[-1:-1] = [
            f"(lo–hi) after a time per iteration or a ratio: its {100 * i['level']:.0f} % interval, "
            f"a {i['kind']} ({i['draws']} draws of the cases with replacement, the same draw for "
            f"every method, seed {i['seed']}; a case that did not converge is left out of that "
            "method's median): how far the choice of cases moves it within this run. Shifts "
            "between runs (the host's load) are not in it.",
        ]
    for task in ("iiwa-com", "iiwa-distance", "drone"):
        if task not in s["tasks"]:
            continue
        ms = s["tasks"][task]
        base = _baseline(task)
        ci = s.get("intervals", {}).get(task, {})
        lines += [
            f"## {task}",
            "",
            "| method | solved & verified | converged | median iters | time/iter [ms] "
            f"| total [ms] | total / {base} | solve [ms] | solve / {base} "
            f"| time/iter / {base} |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        b = ms.get(base, {})
        for name, m in ms.items():
            c = ci.get(name, {})
            ratios = (
                _within(_quotient(m[key], b.get(key)), c.get(f"{what}_ratio"))
                for key, what in (
                    ("median_total_time_s", "total"),
                    ("median_solve_time_s", "solve"),
                    ("median_time_per_iter_s", "time_per_iter"),
                )
            )
            total, solve, per_iter = ratios
            lines.append(
                f"| {name} | {m['verified']}/{m['n']} | {m['converged']}/{m['n']} "
                f"| {_fmt(m['median_iters'])} "
                f"| {_within(m['median_time_per_iter_s'], c.get('time_per_iter_s'), 1e3)} "
                f"| {_fmt(m['median_total_time_s'], 1e3)} | {total} "
                f"| {_fmt(m.get('median_solve_time_s'), 1e3)} | {solve} | {per_iter} |"
            )
        lines += ["", "Statuses: " + "; ".join(f"{n}: {m['statuses']}" for n, m in ms.items()), ""]
    for task, title in (
        ("chain", "Chain reach (N = 40, no obstacles)"),
        ("chain-obstacle", "Chain reach around a cylinder (N = 40, eq. 62, joint speed limits)"),
    ):
        if task in s["tasks"]:
            lines += _chain_table(s["tasks"][task], title)
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
        "stored factor entries (millions). metis: METIS's nested dissection (opt-in "
        '`kkt_ordering` "metis" or "auto", the cheaper of amd and metis; '
        "without pivoting it breaks down on the first iterations' KKT matrices); "
        "nested: dissection by BFS levels of the graph; grid-nd: "
        "dissection of the time × body grid by coordinates; time-/body-major: AMD's order made to eliminate the "
        "time × body grid knot by knot (a stage-wise, Riccati-like elimination) or body by body; "
        "stage-dense: a block-tridiagonal LDLᵀ with dense knot blocks (each knot's unknowns, "
        "multipliers and condensed slacks one dense block, as a batched-LAPACK Riccati recursion "
        "would factor them).",
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


def _chain_table(ch: dict, title: str) -> list[str]:
    links = list(next(iter(ch.values())))
    lines = [
        f"## {title}, RIPM vs generalized IPOPT",
        "",
        "Warm solves from the linear warm start (a cold solve with compilation and symbolic "
        "analysis runs first).",
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
    return [*lines, ""]


def _chain_plot(s: dict, links: tuple[int, ...], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mbplan.benchmarks.common import save_plot

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    x = np.array(links, dtype=float)
    for task, fill in (("chain", "full"), ("chain-obstacle", "none")):
        ch = s["tasks"].get(task)
        for m, style in (("ripm", "o-"), ("ipopt", "s--")) if ch else ():
            per = [ch[m][str(k)]["median_time_per_iter_s"] for k in links]
            tot = [ch[m][str(k)]["median_total_time_s"] for k in links]
            for ax, ys in zip(axes, (per, tot), strict=True):
                ax.loglog(
                    x, [np.nan if v is None else v for v in ys], style, fillstyle=fill,
                    label=f"{m}, {task}",
                )  # fmt: skip
    for ax, what in zip(axes, ("time per iteration [s]", "total time [s]"), strict=True):
        ref = ax.get_lines()[0].get_ydata()[0]
        if np.isfinite(ref):
            ax.loglog(x, ref * (x / x[0]) ** 1.5, "k:", lw=0.8, label="∝ n^1.5")
        ax.set_xlabel("links")
        ax.set_ylabel(what)
        ax.legend(fontsize=8)
    fig.suptitle("Chain reach, N = 40: maximal (RIPM) vs generalized (IPOPT)")
    fig.tight_layout()
    save_plot(fig, out / "chain_scaling.png", dpi=110)


def chain_case(method: str, links: int, obstacle: bool = False) -> dict:
    """One chain reach solve (``ripm`` or ``ipopt``; ``obstacle``: around the cylinder) from the
    linear warm start, with its verification, as a JSON row. The linear start crosses the
    obstacle; the via warm start's random via points are poor starts for long chains."""
    ocp = chain_task(links, obstacle=obstacle)
    workspace = Workspace()
    t0 = time.perf_counter()
    plan(ocp, method, warm_start="linear", workspace=workspace)  # cold: compilation, symbolic
    cold = time.perf_counter() - t0
    row, _, _ = plan_row(
        ocp, method, warm_start="linear", tol=1e-6, max_iter=500, workspace=workspace
    )
    return {"cold_total_time_s": cold, **row}
