"""Closed-loop mechanisms: the RIPM (maximal coordinates) against IPOPT (generalized coordinates).

Per mechanism of :mod:`mbplan.tasks.mechanisms` (``fourbar``, ``delta``, ``two_arm_carry``):
case 0 is the example task, cases ``1..n-1`` its seeded randomizations. Every method plans every
case through :func:`mbplan.plan` from the same warm start (:data:`~mbplan.tasks.mechanisms.WARM_START`),
verified by :func:`mbplan.verify`, in one run, the methods' order alternating case by case.
Timing: before its first timed plan of a mechanism, each process makes one discarded warm-up plan
of case 0 with the method (:data:`WARM_UP_ITERATIONS` iterations), which compiles the kernels and
builds the structures its plans of that mechanism share (one :class:`~mbplan.workspace.Workspace`
per mechanism and method); the rows' ``compile_time_s`` shows what a timed plan still compiled.

Regenerate: ``mbplan bench loops --n 10 --seed 0 --out benchmarks/results/loops``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.benchmarks.common import (
    machine_info,
    median_ratio_interval,
    plan_row,
    save_plot,
    write_atomic,
    write_json,
)
from mbplan.benchmarks.harness import Job, run_jobs, summarize
from mbplan.benchmarks.speed import ratio_intervals
from mbplan.benchmarks.speed_report import INTERVALS, fmt, quotient, within
from mbplan.errors import InputError
from mbplan.planning.solve import check_plan_request, plan
from mbplan.tasks.mechanisms import DT, MECHANISMS, TOL, WARM_START, N, mechanism_case
from mbplan.validation import as_int, as_real
from mbplan.workspace import Workspace

METHODS = ("ripm", "ipopt")
BASELINE = "ipopt"  # the method the others' times are divided by
MAX_ITER = 500
WARM_UP_ITERATIONS = 5

# process-wide, result-neutral (a workspace only keeps structures a plan would build anyway):
# the workspace of each (mechanism, method) after its warm-up plan in this process
_WORKSPACES: dict[tuple[str, str], Workspace] = {}


def _workspace(mechanism: str, method: str, tol: float) -> Workspace:
    """The workspace of ``(mechanism, method)``, after this process's warm-up plan."""
    key = (mechanism, method)
    if key not in _WORKSPACES:
        workspace = Workspace()
        plan(
            mechanism_case(mechanism, 0),
            method,
            warm_start=WARM_START,
            tol=tol,
            max_iter=WARM_UP_ITERATIONS,
            workspace=workspace,
        )
        _WORKSPACES[key] = workspace
    return _WORKSPACES[key]


def solve_case(
    mechanism: str, method: str, seed: int, index: int, tol: float, max_iter: int
) -> dict[str, Any]:
    """Case ``index`` of ``mechanism`` planned by ``method`` (after the warm-up), verified, as a
    JSON row (:func:`~mbplan.benchmarks.common.plan_row`, with the closure residual)."""
    workspace = _workspace(mechanism, method, tol)
    ocp = mechanism_case(mechanism, index, seed)
    row, _, _ = plan_row(
        ocp, method, warm_start=WARM_START, tol=tol, max_iter=max_iter, workspace=workspace
    )
    return row


def check_request(
    mechanisms: Sequence[str], methods: Sequence[str], n: int, seed: int, tol: float, max_iter: int
) -> None:
    """:class:`InputError` naming an unknown mechanism or method, a method that cannot plan a
    mechanism, or a bad number — before any solve."""
    as_int(n, "n", minimum=1, what="number of cases")
    as_int(seed, "seed", minimum=0, what="random seed")
    as_real(tol, "tol", positive=True)
    as_int(max_iter, "max_iter", minimum=1, what="iteration limit")
    for what, given in (("mechanism", mechanisms), ("method", methods)):
        if not given or len(set(given)) != len(given):
            raise InputError(f"loops benchmark: expected distinct {what}s, got {list(given)}")
    unknown = [m for m in mechanisms if m not in MECHANISMS]
    if unknown:
        raise InputError(f"unknown mechanism {unknown[0]!r}; choose from {', '.join(MECHANISMS)}")
    for mechanism in mechanisms:
        ocp = mechanism_case(mechanism, 0, seed)
        for method in methods:
            check_plan_request(ocp, method, tol, max_iter)


def _jobs(
    mechanism: str, methods: Sequence[str], n: int, seed: int, tol: float, max_iter: int
) -> list[Job]:
    """Every (case, method), case by case, the methods' order reversed every other case."""
    return [
        Job(i, m, solve_case, (mechanism, m, seed, i, tol, max_iter))
        for i in range(n)
        for m in (methods if i % 2 == 0 else methods[::-1])
    ]


def _paired_ratio(rows: list[dict], method: str, key: str = "total_time_s") -> dict[str, Any]:
    """The median over the cases both ``method`` and :data:`BASELINE` converged on of the
    per-case ratio of ``key``, with its bootstrap interval (``None`` below
    :data:`~mbplan.benchmarks.common.MIN_INTERVAL_CASES` cases)."""
    own = {r["case"]: r[key] for r in rows if r["method"] == method and r["success"]}
    base = {r["case"]: r[key] for r in rows if r["method"] == BASELINE and r["success"]}
    ratios = {c: own[c] / base[c] for c in own.keys() & base.keys() if base[c] > 0}
    draw = {k: INTERVALS[k] for k in ("level", "draws", "seed")}
    return {
        "cases": len(ratios),
        "median": float(np.median(list(ratios.values()))) if ratios else None,
        "interval": median_ratio_interval(ratios, **draw),
    }


def mechanism_summary(rows: list[dict], mechanism: str, tol: float) -> dict[str, Any]:
    """:func:`~mbplan.benchmarks.harness.summarize` of one mechanism's rows (medians over the
    converged runs) with each method's statuses, closure residuals, compile times and failed
    cases, and the ratios of every method's times to :data:`BASELINE`'s."""
    summary = summarize(rows, mechanism, tol)
    intervals = ratio_intervals(rows, BASELINE)
    base = summary["methods"].get(BASELINE, {})
    for method, entry in summary["methods"].items():
        own = sorted((r for r in rows if r["method"] == method), key=lambda r: r["case"])
        ok = [r for r in own if r["success"]]
        closure = [r["closure_residual"] for r in ok if r.get("closure_residual") is not None]
        statuses = sorted({r["status"] for r in own})
        entry["statuses"] = {s: sum(r["status"] == s for r in own) for s in statuses}
        entry["median_compile_time_s"] = float(np.median([r["compile_time_s"] for r in own]))
        entry["median_closure_residual"] = float(np.median(closure)) if closure else None
        entry["max_closure_residual"] = float(np.max(closure)) if closure else None
        entry["failures"] = [
            {
                "case": r["case"],
                "status": r["status"],
                "success": r["success"],
                "iterations": r["iterations"],
                "closure_residual": r.get("closure_residual"),
                "reasons": r["verification_reasons"],
            }
            for r in own
            if not (r["success"] and r["verified"])
        ]
        if method != BASELINE and BASELINE in summary["methods"]:
            entry["total_ratio"] = quotient(
                entry["median_total_time_s"], base.get("median_total_time_s")
            )
            entry["total_ratio_interval"] = intervals[method].get("total_ratio")
            entry["solve_ratio"] = quotient(
                entry["median_solve_time_s"], base.get("median_solve_time_s")
            )
            entry["solve_ratio_interval"] = intervals[method].get("solve_ratio")
            entry["paired_total_ratio"] = _paired_ratio(rows, method)
    return summary


def run(
    out: Path,
    n: int = 10,
    seed: int = 0,
    methods: Sequence[str] = METHODS,
    mechanisms: Sequence[str] = MECHANISMS,
    tol: float = TOL,
    max_iter: int = MAX_ITER,
    workers: int = 1,
    scheduler: str | None = None,
) -> dict[str, Any]:
    """Run the benchmark (module docstring); write one resumable ``MECHANISM.jsonl`` per
    mechanism, summary.json, results.md and total_time.png under ``out``."""
    methods, mechanisms = tuple(methods), tuple(mechanisms)
    check_request(mechanisms, methods, n, seed, tol, max_iter)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    summary: dict[str, Any] = {
        "mechanisms": {},
        "settings": {
            "n": n,
            "seed": seed,
            "methods": list(methods),
            "baseline": BASELINE,
            "tol": tol,
            "max_iter": max_iter,
            "warm_start": WARM_START,
            "N": N,
            "dt": DT,
            "warm_up_iterations": WARM_UP_ITERATIONS,
        },
        "interval_method": INTERVALS,
    }
    for mechanism in mechanisms:
        config = {
            "benchmark": f"loops-{mechanism}",
            "seed": seed,
            "tol": tol,
            "max_iter": max_iter,
            "warm_start": WARM_START,
            "N": N,
            "dt": DT,
            "warm_up_iterations": WARM_UP_ITERATIONS,
            "through": "mbplan.plan(mbplan.tasks.mechanisms.mechanism_case(mechanism, i, seed))",
        }
        jobs = _jobs(mechanism, methods, n, seed, tol, max_iter)
        rows = run_jobs(
            jobs,
            out / f"{mechanism}.jsonl",
            config=config,
            workers=workers,
            scheduler=scheduler,
            description=mechanism,
        )
        keys = {j.key for j in jobs}
        rows = [r for r in rows if (r["case"], r["method"]) in keys]
        summary["mechanisms"][mechanism] = mechanism_summary(rows, mechanism, tol)
    summary["command"] = (
        f"mbplan bench loops --n {n} --seed {seed} --methods {','.join(methods)}"
        + ("" if mechanisms == MECHANISMS else f" --mechanisms {','.join(mechanisms)}")
        + ("" if tol == TOL else f" --tol {tol:g}")
        + ("" if max_iter == MAX_ITER else f" --max-iter {max_iter}")
        + (f" --workers {workers}" if workers != 1 else "")
        + f" --out {out}"
    )
    summary["machine"] = machine_info()
    summary["wall_time_s"] = time.perf_counter() - t0
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", markdown(summary))
    plot(summary, out / "total_time.png")
    return summary


def markdown(s: dict[str, Any]) -> str:
    """results.md of a :func:`run` summary."""
    st, m = s["settings"], s["machine"]
    iv = s["interval_method"]
    lines = [
        "# Closed-loop mechanisms: RIPM (maximal) vs IPOPT (generalized)",
        "",
        f"Command: `{s['command']}`  ",
        f"Machine: {m['processor']}, {m['cpus']} CPUs, Python {m['python']}, CasADi "
        f"{m['casadi']}, NumPy {m['numpy']} (shared with other jobs: only ratios mean anything).",
        "",
        f"Per mechanism, case 0 is the example task (`examples/tasks/`) and cases 1..{st['n'] - 1} "
        f"draw its goal (`mbplan.tasks.mechanisms`, seed {st['seed']}); every method plans "
        f"every case through `mbplan.plan` from the same `{st['warm_start']}` warm start "
        f"(N = {st['N']}, Δt = {st['dt']} s, tol {st['tol']:g}, at most {st['max_iter']} "
        "iterations), verified by `mbplan.verify`, in one run, the methods' order alternating "
        "case by case.",
        "",
        f"Timing: each process first makes one discarded warm-up plan per mechanism and method "
        f"(case 0, {st['warm_up_iterations']} iterations), so compiling the kernels and building "
        "the structures the method's plans of the mechanism share are not timed; *compile* is "
        "what the timed plans still compiled (median over all runs). *total* is the wall time of `mbplan.plan` "
        "(warm start, formulation, solve, result; it includes *compile*), *solve* the solver's "
        "own. Iterations, times and the closure residual (the largest loop-closure residual at "
        "the knots, from `mbplan.verify`) are medians over the converged runs. "
        f"*total / {s['settings']['baseline']}*: the ratio of the medians; *paired*: the median "
        "of the per-case ratios over the cases both converged on. (lo–hi): the "
        f"{100 * iv['level']:.0f} % interval of a {iv['kind']} ({iv['draws']} draws, seed "
        f"{iv['seed']}), given from 10 cases on.",
        "",
    ]
    base = st["baseline"]
    for mechanism, ms in s["mechanisms"].items():
        lines += [
            f"## {mechanism}",
            "",
            "| method | solved & verified | converged | median iters | time/iter [ms] "
            f"| total [s] | solve [s] | compile [s] | closure residual | total / {base} "
            f"| paired total / {base} | solve / {base} |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for method, e in ms["methods"].items():
            paired = e.get("paired_total_ratio")
            closure = e["median_closure_residual"]
            lines.append(
                f"| {method} | {e['verified']}/{e['n']} | {e['converged']}/{e['n']} "
                f"| {fmt(e['median_iters'])} | {fmt(e['median_time_per_iter_s'], 1e3, 2)} "
                f"| {fmt(e['median_total_time_s'], digits=3)} "
                f"| {fmt(e['median_solve_time_s'], digits=3)} "
                f"| {fmt(e['median_compile_time_s'], digits=3)} "
                f"| {'—' if closure is None else f'{closure:.1e}'} "
                f"| {within(e.get('total_ratio'), e.get('total_ratio_interval'))} "
                + (
                    f"| {within(paired['median'], paired['interval'])} "
                    f"({paired['cases']} case{'' if paired['cases'] == 1 else 's'}) "
                    if paired
                    else "| — "
                )
                + f"| {within(e.get('solve_ratio'), e.get('solve_ratio_interval'))} |"
            )
        lines += [
            "",
            "Statuses: " + "; ".join(f"{k}: {e['statuses']}" for k, e in ms["methods"].items()),
        ]
        failed = [(k, f) for k, e in ms["methods"].items() for f in e["failures"]]
        if failed:
            lines += ["", "Not solved & verified:", ""]
            for k, f in failed:
                closure = f["closure_residual"]
                why = "; ".join(f["reasons"]) or "verification passed"
                lines.append(
                    f"- case {f['case']}, {k}: {f['status']} after {f['iterations']} iterations"
                    f" (success {f['success']}, closure residual "
                    f"{'—' if closure is None else f'{closure:.1e}'}): {why}"
                )
        lines.append("")
    lines.append(f"Wall time of the run: {s['wall_time_s']:.0f} s.")
    return "\n".join(lines) + "\n"


def plot(s: dict[str, Any], path: Path) -> None:
    """Bars of the median total time per mechanism and method (log scale), each labelled with
    its solved & verified count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mechanisms = list(s["mechanisms"])
    methods = s["settings"]["methods"]
    width = 0.8 / len(methods)
    fig, ax = plt.subplots(figsize=(2.2 + 2.0 * len(mechanisms), 4))
    ax.set_yscale("log")
    labels = []
    for j, method in enumerate(methods):
        x = np.arange(len(mechanisms)) + (j - (len(methods) - 1) / 2) * width
        entries = [s["mechanisms"][k]["methods"][method] for k in mechanisms]
        heights = [
            np.nan if e["median_total_time_s"] is None else e["median_total_time_s"]
            for e in entries
        ]
        ax.bar(x, heights, width, label=method)
        labels += [
            (xi, h, f"{e['verified']}/{e['n']}")
            for xi, h, e in zip(x, heights, entries, strict=True)
        ]
    floor = ax.get_ylim()[0]
    for xi, h, label in labels:
        solved = np.isfinite(h)
        text = label if solved else f"{label}\nnone converged"
        ax.annotate(text, (xi, h if solved else floor), ha="center", va="bottom", fontsize=8)
    ax.set_xticks(np.arange(len(mechanisms)), mechanisms)
    ax.set_ylabel("median total time [s] (converged runs)")
    ax.set_title("Closed-loop mechanisms: RIPM vs IPOPT (label: solved & verified)")
    ax.legend()
    fig.tight_layout()
    save_plot(fig, path, dpi=110)
