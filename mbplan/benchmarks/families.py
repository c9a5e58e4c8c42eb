"""Benchmarks over families of seeded cases: every method plans every case of every family
through :func:`mbplan.plan` from the family's warm start, verified by :func:`mbplan.verify`.

A :class:`Suite` names its families (:class:`Family`: ``case(index, seed) -> OCP``, picklable);
:func:`run` writes one resumable ``FAMILY.jsonl`` per family, ``summary.json``, ``results.md``
(per family: solved & verified, iterations, times and the ratios to the baseline method, the
statuses, and every case a method did not solve and verify with its status and reasons) and
``total_time.png``. Jobs run case by case, the methods' order reversed every other case, so that
slow and fast phases of a shared machine fall on every method alike.

Timing: before its first timed plan of a family, each process makes one discarded warm-up plan
of case 0 with each method (:data:`WARM_UP_ITERATIONS` iterations), which compiles the kernels
and builds the structures its plans of the family share (one
:class:`~mbplan.workspace.Workspace` per family and method); ``compile_time_s`` shows what a
timed plan still compiled (a family whose cases differ in robot compiles per robot).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
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
from mbplan.ocp.problem import OCP
from mbplan.planning.solve import check_plan_request, plan
from mbplan.validation import as_int, as_real
from mbplan.workspace import Workspace

WARM_UP_ITERATIONS = 5


@dataclass(frozen=True)
class Family:
    """Seeded cases of one kind: ``case(index, seed)`` builds case ``index`` (a module-level
    function, so that jobs pickle); ``about`` says in one sentence what the cases are."""

    name: str
    case: Callable[[int, int], OCP]
    warm_start: str
    about: str


@dataclass(frozen=True)
class Suite:
    """A benchmark over families: its CLI name, title and an introduction for results.md."""

    name: str
    title: str
    families: Mapping[str, Family]
    intro: str
    methods: tuple[str, ...] = ("ripm", "ipopt")
    baseline: str = "ipopt"
    tol: float = 1e-6
    max_iter: int = 500
    n: int = 10
    extra_columns: tuple[str, ...] = field(default=())
    """Row keys shown as a median column over the converged runs (e.g. ``closure_residual``)."""
    family_flag: str = "families"
    """The CLI option that selects families."""
    family_noun: str = "family"
    """What the suite calls a family in messages."""


# process-wide, result-neutral (a workspace only keeps structures a plan would build anyway):
# the workspace of each (family, method) after its warm-up plan in this process
_WORKSPACES: dict[tuple[str, str], Workspace] = {}


def _workspace(family: Family, method: str, seed: int, tol: float) -> Workspace:
    """The workspace of ``(family, method)``, after this process's warm-up plan."""
    key = (family.name, method)
    if key not in _WORKSPACES:
        workspace = Workspace()
        plan(
            family.case(0, seed),
            method,
            warm_start=family.warm_start,
            tol=tol,
            max_iter=WARM_UP_ITERATIONS,
            workspace=workspace,
        )
        _WORKSPACES[key] = workspace
    return _WORKSPACES[key]


def solve_case(
    family: Family, method: str, seed: int, index: int, tol: float, max_iter: int
) -> dict[str, Any]:
    """Case ``index`` of ``family`` planned by ``method`` (after the warm-up), verified, as a
    JSON row (:func:`~mbplan.benchmarks.common.plan_row`) with the case's description."""
    workspace = _workspace(family, method, seed, tol)
    ocp = family.case(index, seed)
    row, _, _ = plan_row(
        ocp, method, warm_start=family.warm_start, tol=tol, max_iter=max_iter, workspace=workspace
    )
    row["description"] = describe(ocp)
    return row


def describe(ocp: OCP) -> str:
    """A case in a few words: its robot (joints) and obstacles."""
    obstacles = len(ocp.scene) if ocp.scene is not None else 0
    return f"{ocp.robot.name} ({ocp.robot.nq} joints)" + (
        f", {obstacles} obstacle{'' if obstacles == 1 else 's'}" if obstacles else ""
    )


def check_request(
    suite: Suite,
    families: Sequence[str],
    methods: Sequence[str],
    n: int,
    seed: int,
    tol: float,
    max_iter: int,
) -> None:
    """:class:`InputError` naming an unknown family or method, a method that cannot plan a
    family, or a bad number — before any solve."""
    as_int(n, "n", minimum=1, what="number of cases")
    as_int(seed, "seed", minimum=0, what="random seed")
    as_real(tol, "tol", positive=True)
    as_int(max_iter, "max_iter", minimum=1, what="iteration limit")
    for what, given in ((suite.family_noun, families), ("method", methods)):
        if not given or len(set(given)) != len(given):
            raise InputError(
                f"{suite.name} benchmark: expected one or more distinct {what} names, got "
                f"{list(given)}"
            )
    unknown = [f for f in families if f not in suite.families]
    if unknown:
        raise InputError(
            f"{suite.name} benchmark: unknown {suite.family_noun} {unknown[0]!r}; choose from "
            f"{', '.join(suite.families)}"
        )
    for name in families:
        ocp = suite.families[name].case(0, seed)
        for method in methods:
            check_plan_request(ocp, method, tol, max_iter)


def _jobs(
    family: Family, methods: Sequence[str], n: int, seed: int, tol: float, max_iter: int
) -> list[Job]:
    """Every (case, method), case by case, the methods' order reversed every other case."""
    return [
        Job(i, m, solve_case, (family, m, seed, i, tol, max_iter))
        for i in range(n)
        for m in (methods if i % 2 == 0 else methods[::-1])
    ]


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


def command(
    suite: Suite,
    out: Path,
    n: int,
    seed: int,
    methods: Sequence[str],
    families: Sequence[str],
    tol: float,
    max_iter: int,
    workers: int,
) -> str:
    """The ``mbplan bench`` command line that regenerates a run."""
    return (
        f"mbplan bench {suite.name} --n {n} --seed {seed} --methods {','.join(methods)}"
        + (
            ""
            if tuple(families) == tuple(suite.families)
            else f" --{suite.family_flag} {','.join(families)}"
        )
        + ("" if tol == suite.tol else f" --tol {tol:g}")
        + ("" if max_iter == suite.max_iter else f" --max-iter {max_iter}")
        + (f" --workers {workers}" if workers != 1 else "")
        + f" --out {out}"
    )


def _call(case: Callable[[int, int], OCP]) -> str:
    """How a family builds case ``i``: ``module.function(fixed arguments..., i, seed)``."""
    fn, fixed = getattr(case, "func", case), getattr(case, "args", ())
    return f"{fn.__module__}.{fn.__qualname__}({''.join(f'{a!r}, ' for a in fixed)}i, seed)"


def run(
    suite: Suite,
    out: Path,
    n: int | None = None,
    seed: int = 0,
    methods: Sequence[str] | None = None,
    families: Sequence[str] | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    workers: int = 1,
    scheduler: str | None = None,
) -> dict[str, Any]:
    """Run ``suite`` (module docstring); ``None`` takes the suite's default. Writes one
    resumable ``FAMILY.jsonl`` per family, summary.json, results.md and total_time.png under
    ``out`` and returns the summary."""
    n = suite.n if n is None else n
    methods = tuple(suite.methods if methods is None else methods)
    families = tuple(suite.families if families is None else families)
    tol = suite.tol if tol is None else tol
    max_iter = suite.max_iter if max_iter is None else max_iter
    check_request(suite, families, methods, n, seed, tol, max_iter)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    summary: dict[str, Any] = {
        "families": {},
        "settings": {
            "n": n,
            "seed": seed,
            "methods": list(methods),
            "baseline": suite.baseline,
            "tol": tol,
            "max_iter": max_iter,
            "warm_up_iterations": WARM_UP_ITERATIONS,
        },
        "interval_method": INTERVALS,
    }
    for name in families:
        family = suite.families[name]
        config = {
            "benchmark": f"{suite.name}-{name}",
            "seed": seed,
            "tol": tol,
            "max_iter": max_iter,
            "warm_start": family.warm_start,
            "warm_up_iterations": WARM_UP_ITERATIONS,
            "through": f"mbplan.plan({_call(family.case)})",
        }
        jobs = _jobs(family, methods, n, seed, tol, max_iter)
        rows = run_jobs(
            jobs,
            out / f"{name}.jsonl",
            config=config,
            workers=workers,
            scheduler=scheduler,
            description=name,
        )
        keys = {j.key for j in jobs}
        rows = [r for r in rows if (r["case"], r["method"]) in keys]
        entry = family_summary(rows, name, tol, suite.baseline, suite.extra_columns)
        entry.update(about=family.about, warm_start=family.warm_start)
        summary["families"][name] = entry
    summary["command"] = command(suite, out, n, seed, methods, families, tol, max_iter, workers)
    summary["machine"] = machine_info()
    summary["wall_time_s"] = time.perf_counter() - t0
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", markdown(suite, summary))
    plot(suite, summary, out / "total_time.png")
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


def markdown(suite: Suite, s: dict[str, Any]) -> str:
    """results.md of a :func:`run` summary."""
    st, m = s["settings"], s["machine"]
    iv = s["interval_method"]
    base = st["baseline"]
    lines = [
        f"# {suite.title}",
        "",
        f"Command: `{s['command']}`  ",
        f"Machine: {m['processor']}, {m['cpus']} CPUs, Python {m['python']}, CasADi "
        f"{m['casadi']}, NumPy {m['numpy']} (shared with other jobs: only ratios mean anything).",
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
            cells = "".join(
                " | —" if e[f"median_{key}"] is None else f" | {e[f'median_{key}']:.1e}"
                for key in suite.extra_columns
            )
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
                    f"{key.replace('_', ' ')} {f[key]:.1e}"
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
