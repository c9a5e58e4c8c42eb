"""Speed of the RIPM against the baselines on its own tasks, with a per-iteration profile.

Tasks: :mod:`mbplan.tasks.speed`; profile and orderings:
:mod:`mbplan.benchmarks.kkt_profile`.
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.benchmarks.cold_start import cold_starts
from mbplan.benchmarks.common import plan_row
from mbplan.benchmarks.kkt_profile import ordering_stats, profile_solve
from mbplan.benchmarks.speed_report import INTERVALS, baseline, chain_plot, markdown
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


def _by_case(rows: list[dict], key: str) -> dict[Any, float | None]:
    """``key`` of one method's rows by case, ``None`` where it did not converge (as :func:`_med`)."""
    return {r["case"]: r.get(key) if r["success"] else None for r in rows}


def _total_key(rows: list[dict]) -> str:
    """The key of a method's *total* time: its total, or its solve time where it has none
    (as :func:`_method_stats`)."""
    return "total_time_s" if _med(rows, "total_time_s") else "solve_time_s"


def ratio_intervals(
    rows: list[dict], base: str
) -> dict[str, dict[str, tuple[float, float] | None]]:
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
            summary["intervals"][name] = ratio_intervals(rows, baseline(name))
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
    summary["cold"] = cold_starts()
    summary["command"] = (
        f"mbplan bench speed --n-iiwa {n_iiwa} --n-iiwa-distance {n_dist} --n-drone {n_drone} "
        f"--links {','.join(map(str, links))} --seed {seed} --workers {workers} --out {out}"
    )
    summary["machine"] = machine_info()
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", markdown(summary))
    if {"chain", "chain-obstacle"} & set(rows_by_task):
        chain_plot(summary, links, out)
    return summary


def run_cold(out: Path, repeats: int = 3) -> dict:
    """The ``cold`` section alone (:func:`~mbplan.benchmarks.cold_start.cold_starts`), put into
    the summary already in ``out`` (if any: the other sections are kept as they are) and
    rendered with it."""
    from mbplan.benchmarks.common import machine_info, write_atomic, write_json

    out.mkdir(parents=True, exist_ok=True)
    path = out / "summary.json"
    summary = json.loads(path.read_text()) if path.is_file() else {"tasks": {}}
    summary["cold"] = cold_starts(repeats=repeats)
    summary.setdefault("command", f"mbplan bench speed --cold-only --out {out}")
    summary.setdefault("machine", machine_info())
    write_json(path, summary)
    write_atomic(out / "results.md", markdown(summary))
    return summary


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
