"""The reports of a :mod:`mbplan.benchmarks.families` run: each family's summary (medians over
the converged runs, statuses, failed cases, ratios to the baseline), results.md and the plot."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mbplan.benchmarks.common import median_ratio_interval, save_plot
from mbplan.benchmarks.harness import summarize
from mbplan.benchmarks.speed import ratio_intervals
from mbplan.benchmarks.speed_report import INTERVALS, fmt, quotient, within

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mbplan.benchmarks.families import Suite


def _paired_ratio(rows: list[dict], method: str, baseline: str) -> dict[str, Any]:
    """The median over the cases both ``method`` and ``baseline`` converged on of the per-case
    ratio of the total times, with its bootstrap interval (``None`` below
    :data:`~mbplan.benchmarks.common.MIN_INTERVAL_CASES` cases)."""
    own = {r["case"]: r["total_time_s"] for r in rows if r["method"] == method and r["success"]}
    base = {r["case"]: r["total_time_s"] for r in rows if r["method"] == baseline and r["success"]}
    ratios = {c: own[c] / base[c] for c in own.keys() & base.keys() if base[c] > 0}
    draw = {k: INTERVALS[k] for k in ("level", "draws", "seed")}
    return {
        "cases": len(ratios),
        "median": float(np.median(list(ratios.values()))) if ratios else None,
        "interval": median_ratio_interval(ratios, **draw),
    }


def family_summary(
    rows: list[dict], family: str, tol: float, baseline: str, extra: Sequence[str] = ()
) -> dict[str, Any]:
    """:func:`~mbplan.benchmarks.harness.summarize` of one family's rows (medians over the
    converged runs) with each method's statuses, compile times, ``extra`` columns and failed
    cases, the ratios of every method's times to ``baseline``'s, and the cases the baseline
    solved and verified that another method did not."""
    summary = summarize(rows, family, tol)
    intervals = ratio_intervals(rows, baseline)
    base = summary["methods"].get(baseline, {})
    solved = {
        m: {r["case"] for r in rows if r["method"] == m and r["success"] and r["verified"]}
        for m in summary["methods"]
    }
    for method, entry in summary["methods"].items():
        own = sorted((r for r in rows if r["method"] == method), key=lambda r: r["case"])
        ok = [r for r in own if r["success"]]
        statuses = sorted({r["status"] for r in own})
        entry["statuses"] = {s: sum(r["status"] == s for r in own) for s in statuses}
        entry["median_compile_time_s"] = float(np.median([r["compile_time_s"] for r in own]))
        for key in extra:
            values = [r[key] for r in ok if r.get(key) is not None]
            entry[f"median_{key}"] = float(np.median(values)) if values else None
        entry["failures"] = [
            {
                "case": r["case"],
                "description": r.get("description", ""),
                "status": r["status"],
                "success": r["success"],
                "iterations": r["iterations"],
                "baseline_solved": r["case"] in solved.get(baseline, set()),
                "reasons": r["verification_reasons"],
                **{key: r.get(key) for key in extra},
            }
            for r in own
            if not (r["success"] and r["verified"])
        ]
        if method != baseline and baseline in summary["methods"]:
            entry["behind_baseline"] = sorted(solved[baseline] - solved[method])
            entry["total_ratio"] = quotient(
                entry["median_total_time_s"], base.get("median_total_time_s")
            )
            entry["total_ratio_interval"] = intervals[method].get("total_ratio")
            entry["solve_ratio"] = quotient(
                entry["median_solve_time_s"], base.get("median_solve_time_s")
            )
            entry["solve_ratio_interval"] = intervals[method].get("solve_ratio")
            entry["paired_total_ratio"] = _paired_ratio(rows, method, baseline)
    return summary


def _totals(s: dict[str, Any]) -> list[str]:
    """Solved & verified per family and method, with the cases the baseline solved and
    verified that the method did not."""
    methods, base = s["settings"]["methods"], s["settings"]["baseline"]
    lines = [
        "| family | " + " | ".join(methods) + f" | {base} only |",
        "|---|" + "---:|" * (len(methods) + 1),
    ]
    done = dict.fromkeys(methods, 0)
    total = dict.fromkeys(methods, 0)
    for name, fs in s["families"].items():
        cells = []
        for method in methods:
            e = fs["methods"][method]
            done[method] += e["verified"]
            total[method] += e["n"]
            cells.append(f"{e['verified']}/{e['n']}")
        behind = {
            c for m in methods if m != base for c in fs["methods"][m].get("behind_baseline", ())
        }
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {len(behind)} |")
    cells = [f"{done[m]}/{total[m]} ({100 * done[m] / total[m]:.0f} %)" for m in methods]
    return [*lines, "| **all** | " + " | ".join(cells) + " | |"]


PERCENT_COLUMNS = ("margin_kept",)
"""Extra columns that are fractions, shown in percent (the others in scientific notation)."""


def _extra(key: str, value: float | None) -> str:
    """An extra column's cell."""
    if value is None:
        return "—"
    return f"{100 * value:.0f} %" if key in PERCENT_COLUMNS else f"{value:.1e}"


def _workers(settings: dict[str, Any]) -> str:
    """How the run shared the machine: its worker processes and their threads."""
    workers, threads = settings["workers"], settings["threads_per_worker"]
    if workers is None:
        return ", a Dask cluster's workers"
    if workers == 1:
        return ", one process"
    return f", {workers} worker processes of {threads} thread{'s' * (threads > 1)} each"


def markdown(suite: Suite, s: dict[str, Any]) -> str:
    """results.md of a :func:`run` summary."""
    st, m = s["settings"], s["machine"]
    iv = s["interval_method"]
    base = st["baseline"]
    lines = [
        f"# {suite.title}",
        "",
        f"Command: `{s['command']}`  ",
        f"Machine: {m['processor']}, {m['cpus']} CPUs{_workers(st)}, Python {m['python']}, "
        f"CasADi {m['casadi']}, NumPy {m['numpy']} (shared with other jobs: only ratios mean "
        "anything).",
        "",
        suite.intro.format(**st),
        "",
        f"Every method plans every case through `mbplan.plan` from the family's warm start (tol "
        f"{st['tol']:g}, at most {st['max_iter']} iterations), verified by `mbplan.verify`, in "
        "one run, the methods' order alternating case by case. Timing: each process first makes "
        f"one discarded warm-up plan per family and method (case 0, {st['warm_up_iterations']} "
        "iterations); *compile* is what the timed plans still compiled (median over all runs). "
        "*total* is the wall time of `mbplan.plan` (warm start, formulation, solve, result; it "
        "includes *compile*), *solve* the solver's own. Iterations and times are medians over "
        f"the converged runs. *total / {base}*: the ratio of the medians; *paired*: the median "
        "of the per-case ratios over the cases both converged on. (lo–hi): the "
        f"{100 * iv['level']:.0f} % interval of a {iv['kind']} ({iv['draws']} draws, seed "
        f"{iv['seed']}), given from 10 cases on.",
        "",
    ]
    if len(s["families"]) > 1:
        lines += ["## All families", "", *_totals(s), ""]
    for name, fs in s["families"].items():
        extra = "".join(f" | {key.replace('_', ' ')}" for key in suite.extra_columns)
        lines += [
            f"## {name}",
            "",
            f"{fs['about']} Warm start: `{fs['warm_start']}`.",
            "",
            "| method | solved & verified | converged | median iters | time/iter [ms] "
            f"| total [s] | solve [s] | compile [s]{extra} | total / {base} "
            f"| paired total / {base} | solve / {base} |",
            "|---|" + "---:|" * (10 + len(suite.extra_columns)),
        ]
        for method, e in fs["methods"].items():
            paired = e.get("paired_total_ratio")
            cells = "".join(f" | {_extra(key, e[f'median_{key}'])}" for key in suite.extra_columns)
            lines.append(
                f"| {method} | {e['verified']}/{e['n']} | {e['converged']}/{e['n']} "
                f"| {fmt(e['median_iters'])} | {fmt(e['median_time_per_iter_s'], 1e3, 2)} "
                f"| {fmt(e['median_total_time_s'], digits=3)} "
                f"| {fmt(e['median_solve_time_s'], digits=3)} "
                f"| {fmt(e['median_compile_time_s'], digits=3)}{cells} "
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
            "Statuses: " + "; ".join(f"{k}: {e['statuses']}" for k, e in fs["methods"].items()),
        ]
        failed = [(k, f) for k, e in fs["methods"].items() for f in e["failures"]]
        if failed:
            lines += [
                "",
                "Not solved & verified:",
                "",
                f"| case | description | method | status | iterations | {base} solved it "
                "| verification |",
                "|---:|---|---|---|---:|---|---|",
            ]
            for k, f in sorted(failed, key=lambda kf: (kf[1]["case"], kf[0])):
                extras = "; ".join(
                    f"{key.replace('_', ' ')} {_extra(key, f[key])}"
                    for key in suite.extra_columns
                    if f.get(key) is not None
                )
                why = "; ".join(f["reasons"]) or "passed"
                lines.append(
                    f"| {f['case']} | {f['description']} | {k} | {f['status']} "
                    f"| {f['iterations']} | {'—' if k == base else ('yes' if f['baseline_solved'] else 'no')} "
                    f"| {why}{f' ({extras})' if extras else ''} |"
                )
        lines.append("")
    if suite.profile_markdown is not None and "profile" in s:
        lines += [*suite.profile_markdown(s["profile"]), ""]
    lines.append(f"Wall time of the run: {s['wall_time_s']:.0f} s.")
    return "\n".join(lines) + "\n"


def plot(suite: Suite, s: dict[str, Any], path: Path) -> None:
    """Bars of the median total time per family and method (log scale), each labelled with
    its solved & verified count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = list(s["families"])
    methods = s["settings"]["methods"]
    width = 0.8 / len(methods)
    fig, ax = plt.subplots(figsize=(2.2 + 2.0 * len(families), 4))
    ax.set_yscale("log")
    labels = []
    for j, method in enumerate(methods):
        x = np.arange(len(families)) + (j - (len(methods) - 1) / 2) * width
        entries = [s["families"][k]["methods"][method] for k in families]
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
    ax.set_xticks(np.arange(len(families)), families, rotation=15)
    ax.set_ylabel("median total time [s] (converged runs)")
    ax.set_title(f"{suite.title} (label: solved & verified)", fontsize=10)
    ax.legend()
    fig.tight_layout()
    save_plot(fig, path, dpi=110)
