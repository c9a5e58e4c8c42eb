"""Benchmarks over families of seeded cases: every method plans every case of every family
through :func:`mbplan.plan` from the family's warm start, verified by :func:`mbplan.verify`.

A :class:`Suite` names its families (:class:`Family`: ``case(index, seed) -> OCP``, picklable);
:func:`run` writes one resumable ``FAMILY.jsonl`` per family, ``summary.json``, ``results.md``
(per family: solved & verified, iterations, times and the ratios to the baseline method, the
statuses, and every case a method did not solve and verify with its status and reasons) and
``total_time.png``. Jobs run case by case, the methods' order reversed every other case, so that
slow and fast phases of a shared machine fall on every method alike.

A plan refused before any solve (:class:`~mbplan.errors.InfeasibleRequestError`: a warm start
that reaches no goal, a start inside an obstacle) is that case's failure, status ``REFUSED``
with the reason, not the run's end.

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

from mbplan.benchmarks.common import machine_info, plan_row, write_atomic, write_json
from mbplan.benchmarks.families_report import family_summary, markdown, plot
from mbplan.benchmarks.harness import Job, run_jobs, worker_threads
from mbplan.benchmarks.speed_report import INTERVALS
from mbplan.errors import InfeasibleRequestError, InputError
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
    n: int | None = None
    """At most this many cases whatever the suite's ``n`` (a published task, repeated for its
    timing); None: the suite's."""

    def cases(self, n: int) -> int:
        """The number of cases of a run asking for ``n`` per family."""
        return n if self.n is None else min(n, self.n)


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
    profile: Callable[[Sequence[str], int], dict[str, Any]] | None = None
    """``profile(families, seed)``, run after the families: a summary entry (``"profile"``)."""
    profile_markdown: Callable[[dict[str, Any]], list[str]] | None = None
    """The results.md section of that entry."""


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
    try:
        row, _, _ = plan_row(
            ocp,
            method,
            warm_start=family.warm_start,
            tol=tol,
            max_iter=max_iter,
            workspace=workspace,
        )
    except InfeasibleRequestError as error:  # refused before a solve: the case's failure
        row = refused_row(error)
    row["description"] = describe(ocp)
    return row


def refused_row(error: InfeasibleRequestError) -> dict[str, Any]:
    """The row of a plan refused before any solve (e.g. a warm start that reaches no goal)."""
    return {
        "success": False,
        "status": "REFUSED",
        "iterations": 0,
        "solve_time_s": 0.0,
        "total_time_s": 0.0,
        "time_per_iter_s": 0.0,
        "compile_time_s": 0.0,
        "verified": False,
        "verification_reasons": [str(error)],
    }


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
        for i in range(family.cases(n))
        for m in (methods if i % 2 == 0 else methods[::-1])
    ]


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
            "workers": workers if scheduler is None else None,
            "threads_per_worker": worker_threads(workers)
            if scheduler is None and workers > 1
            else None,
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
    if suite.profile is not None:
        summary["profile"] = suite.profile(families, seed)
    summary["command"] = command(suite, out, n, seed, methods, families, tol, max_iter, workers)
    summary["machine"] = machine_info()
    summary["wall_time_s"] = time.perf_counter() - t0
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", markdown(suite, summary))
    plot(suite, summary, out / "total_time.png")
    return summary
