"""The MLG-IPM paper's study (§V, Tables I-IV): problems (10) on SO(7)² and (11) on SL(7)².

Every method solves the same seeded instances from the same initial iterate ``G0``:

* ``mlgipm``: :func:`~mbplan.solvers.lie_ipm.mlgipm.solve_mlgipm` with its defaults;
* ``mlgipm-paper``: Algorithm 1 literally (fixed σ = 0.1, τ = 0.995, exact 𝕳_ℒ, no line search);
* ``mlgipm-symmetric``: defaults with the symmetric Riemannian Hessian;
* ``mlgipm-nols``: defaults without the merit line search;
* ``lai-yoshise``: :func:`~mbplan.solvers.lie_ipm.lai_yoshise.solve_lai_yoshise` (the paper's "RIPM");
* ``ripm``: our RIPM (Teng et al.), ``solve_ripm`` with ``max_iter=500``;
* ``ipopt``: IPOPT on the embedded form of (11) (SL only).

``--rho`` perturbs the Newton systems of the MLG-IPM variants and Lai-Yoshise (Tables II, IV).
Success (one meaning for all): the solver reports success **and** the independent KKT residual
``‖F₀‖∞`` at its returned ``(G, ν, s)`` is ≤ 1e-6 (IPOPT: its success and ``|f - f*| ≤ 1e-6``,
its multipliers living in another space). "Error" is ``‖F₀‖₂`` (the paper's "final residual").

Regenerate: ``OPENBLAS_NUM_THREADS=1 mbplan bench lie-ipm --problem so7 --n 1000 --seed 0
--rho 0 --out benchmarks/results/lie-ipm/so7-rho0`` (see ``benchmarks/results/lie-ipm/``).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from mbplan.benchmarks.common import machine_info, save_plot, write_atomic, write_json
from mbplan.benchmarks.harness import Job, run_jobs
from mbplan.benchmarks.lie_ipm_stats import SUMMARY_KEYS, compare, describe
from mbplan.errors import InputError
from mbplan.solvers import solve_ripm
from mbplan.solvers.lie_ipm.kkt_field import PrimalDual, evaluate_field
from mbplan.solvers.lie_ipm.lai_yoshise import LaiYoshiseOptions, solve_lai_yoshise
from mbplan.solvers.lie_ipm.mlgipm import MLGIPMOptions, solve_mlgipm
from mbplan.tasks.lie_ipm import make_problem, sample_instance

PROBLEMS = {"so7": "so", "sl7": "sl"}
METHODS = (
    "mlgipm",
    "mlgipm-paper",
    "mlgipm-symmetric",
    "mlgipm-nols",
    "lai-yoshise",
    "ripm",
    "ipopt",
)
PERTURBABLE = ("mlgipm", "mlgipm-paper", "mlgipm-symmetric", "mlgipm-nols", "lai-yoshise")
SLOW = ("lai-yoshise", "ripm", "ipopt")
TOL = 1e-6
MAX_ITER = 500
PAPER = {
    ("so7", 0.0): {
        "MLG-IPM": (10.5661, 20.0, 0.991, 5.0e-5),
        "RIPM": (20.8154, 500.0, 0.416, 4.7e-3),
    },
    ("so7", 0.01): {
        "MLG-IPM": (11.44, 21.0, 0.973, 4.94e-3),
        "RIPM": (22.29, 500.0, 0.388, 9.9e-3),
    },
    ("sl7", 0.0): {
        "MLG-IPM": (0.1187, 58.0, 0.981, 6.6e-5),
        "RIPM": (6.6486, 500.0, 0.359, 2.7e-3),
    },
    ("sl7", 0.001): {"MLG-IPM": (0.1346, 62.0, 0.937, 5e-4), "RIPM": (6.8945, 500.0, 0.408, 2e-3)},
}


def _mlgipm_options(method: str, rho: float, index: int) -> MLGIPMOptions:
    base = {
        "mlgipm": MLGIPMOptions(),
        "mlgipm-paper": MLGIPMOptions.paper(),
        "mlgipm-symmetric": MLGIPMOptions(curvature="symmetric"),
        "mlgipm-nols": MLGIPMOptions(line_search=False),
    }[method]
    return base.replace(tol=TOL, max_iter=MAX_ITER, rho=rho, rho_seed=index)


def solve_case(
    problem: str, method: str, seed: int, index: int, rho: float, objective: str, constants: str
) -> dict:
    """One (instance, method) solve as a JSON row."""
    inst = sample_instance(PROBLEMS[problem], seed, index)
    nlp = make_problem(inst, objective, constants)
    f_star = nlp.optimum()
    if method == "ipopt":
        if problem != "sl7":
            raise InputError("ipopt: problem (10) has no embedded CasADi form (log on SO(n))")
        from mbplan.baselines.embedded_ipopt import solve_sl_trace_ipopt

        r = solve_sl_trace_ipopt(inst.Gd, inst.G0, nlp.c, max_iter=MAX_ITER, tol=1e-8)
        gap = abs(r["objective"] - f_star)
        return {
            "success": bool(r["success"] and gap <= TOL),
            "status": r["status"],
            "iterations": r["iterations"],
            "time_s": r["time_s"],
            "error": gap,
            "objective": r["objective"],
            "optimality_gap": gap,
            "det_error": r["det_error"],
        }
    if method.startswith("mlgipm"):
        res = solve_mlgipm(nlp, inst.G0, _mlgipm_options(method, rho, index))
    elif method == "lai-yoshise":
        res = solve_lai_yoshise(nlp, inst.G0, LaiYoshiseOptions(rho=rho, seed=index))
    elif method == "ripm":
        res = solve_ripm(nlp, inst.G0, max_iter=MAX_ITER, tol=1e-8)
    else:
        raise InputError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    fv = evaluate_field(nlp, PrimalDual(res.x, res.z, res.y, res.s), hessian=False)
    residual = fv.kkt_error()
    error = fv.norm()
    finite = bool(np.isfinite(error))
    return {
        "success": bool(res.success and finite and residual <= TOL),
        "status": res.status.name,
        "iterations": res.iterations,
        "time_s": res.wall_time_s,
        "error": error if finite else None,
        "kkt_inf": residual if finite else None,
        "objective": res.objective if np.isfinite(res.objective) else None,
        "optimality_gap": None if f_star is None else abs(res.objective - f_star),
        "active": int(np.sum(res.z > 1e-3 * max(1.0, float(np.max(res.z, initial=1.0))))),
    }


def run(
    out: Path,
    problem: str = "so7",
    n: int = 1000,
    seed: int = 0,
    rho: float = 0.0,
    methods: tuple[str, ...] | None = None,
    objective: str = "squared",
    constants: str = "rendered",
    workers: int = 1,
    scheduler: str | None = None,
    n_slow: int | None = None,
) -> dict:
    """Run the study; write results.jsonl, summary.json, statistics.json, results.md, plots.

    ``n_slow`` (≤ n) caps the instances of the slow baselines :data:`SLOW` (the first
    ``n_slow`` instances, the same for every method)."""
    if problem not in PROBLEMS:
        raise InputError(f"problem must be one of {sorted(PROBLEMS)}, got {problem!r}")
    if methods is None:
        methods = (
            PERTURBABLE
            if rho > 0
            else tuple(m for m in METHODS if m != "ipopt" or problem == "sl7")
        )
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        raise InputError(f"unknown methods {unknown}; choose from {', '.join(METHODS)}")
    if rho > 0 and set(methods) - set(PERTURBABLE):
        raise InputError(f"--rho > 0 applies only to {', '.join(PERTURBABLE)}")
    if "ipopt" in methods and problem != "sl7":
        raise InputError("ipopt runs on sl7 only: problem (10) has no embedded CasADi form")
    n_slow = n if n_slow is None else min(n_slow, n)
    count = {m: (n_slow if m in SLOW else n) for m in methods}
    jobs = [
        Job(i, m, solve_case, (problem, m, seed, i, rho, objective, constants))
        for m in methods
        for i in range(count[m])
    ]
    t0 = time.perf_counter()
    rows = run_jobs(
        jobs, out / "results.jsonl", workers=workers, scheduler=scheduler, description=problem
    )
    rows = [r for r in rows if r["method"] in methods and r["case"] < count[r["method"]]]
    described = {m: describe([r for r in rows if r["method"] == m]) for m in methods}
    summary = {
        "problem": problem,
        "methods": {m: {k: d[k] for k in SUMMARY_KEYS} for m, d in described.items()},
    }
    command = (
        f"OPENBLAS_NUM_THREADS=1 mbplan bench lie-ipm --problem {problem} --n {n} --seed {seed} "
        f"--rho {rho:g} --methods {','.join(methods)} --objective {objective} "
        f"--constants {constants}" + (f" --n-slow {n_slow}" if n_slow < n else "") + f" --out {out}"
    )
    meta = {
        "command": command,
        "rho": rho,
        "objective": objective,
        "constants": constants,
        "seed": seed,
        "tol": TOL,
        "max_iter": MAX_ITER,
        "machine": machine_info(),
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        "wall_time_s": time.perf_counter() - t0,
        "describe": described,
        "statuses": {m: _counts([r["status"] for r in rows if r["method"] == m]) for m in methods},
        "comparisons": {
            b: compare(
                [r for r in rows if r["method"] == "mlgipm"],
                [r for r in rows if r["method"] == b],
            )
            for b in methods
            if b != "mlgipm" and "mlgipm" in methods
        },
    }
    write_json(out / "summary.json", summary)
    write_json(out / "statistics.json", meta)
    write_atomic(out / "results.md", _markdown(meta, problem, rho))
    _plots(rows, methods, out, problem)
    return summary


def _counts(values: list[str]) -> dict[str, int]:
    return {v: values.count(v) for v in sorted(set(values))}


def _pm(mean: float | None, sd: float | None, fmt: str) -> str:
    if mean is None:
        return "—"
    return f"{mean:{fmt}} ± {sd:{fmt}}" if sd is not None else f"{mean:{fmt}}"


def _markdown(meta: dict, problem: str, rho: float) -> str:
    ms = meta["describe"]
    names = list(ms)
    head = "| Metric | " + " | ".join(names) + " |"
    sep = "|---|" + "---:|" * len(names)

    def row(label: str, cell) -> str:
        return f"| {label} | " + " | ".join(cell(ms[m]) for m in names) + " |"

    def val(v, fmt):
        return "—" if v is None else f"{v:{fmt}}"

    lines = [
        f"# MLG-IPM study: {problem}, ρ = {rho:g}, objective {meta['objective']}, "
        f"constants {meta['constants']}",
        "",
        f"Command: `{meta['command']}`",
        "",
        "Layout of the paper's Tables I-IV; iterations and times over all runs, error (‖F₀‖₂, "
        "the final residual) over successful runs. Success: solver success and ‖F₀‖∞ ≤ 1e-6 "
        "at the returned point.",
        "",
        head,
        sep,
        row("Time (s) Median", lambda s: val(s["median_time_s"], ".4f")),
        row("Time (s) Mean", lambda s: _pm(s["mean_time_s"], s["sd_time_s"], ".4f")),
        row("Iterations Median", lambda s: val(s["median_iters"], ".1f")),
        row("Iterations Mean", lambda s: _pm(s["mean_iters"], s["sd_iters"], ".2f")),
        row(
            "Success Rate",
            lambda s: f"{s['success'] / max(s['n'], 1):.3f} ({s['success']}/{s['n']})",
        ),
        row("Error Mean", lambda s: _pm(s["error_mean"], s["error_sd"], ".2e")),
        "",
        "Statuses: "
        + "; ".join(
            f"{m}: {', '.join(f'{k} {v}' for k, v in c.items())}"
            for m, c in meta["statuses"].items()
        ),
        "",
    ]
    if meta["comparisons"]:
        lines += [
            "## Statistics: mlgipm against each method (the paper's tests)",
            "",
            "| vs | χ² | p(χ²) | Z | p(Z) | Cramér's V | Lilliefors p (time: mlgipm / other) "
            "| WMW p time | WMW p iters | WMW p error | Cohen's d time | Cohen's d iters |",
            "|---|" + "---:|" * 11,
        ]
        for b, c in meta["comparisons"].items():
            lines.append(
                f"| {b} | {c['chi2']:.2f} | {c['chi2_p']:.2g} | {c['z']:.2f} | {c['z_p']:.2g} | "
                f"{c['cramers_v']:.3f} | {val(c['lilliefors_p_time'][0], '.3g')} / "
                f"{val(c['lilliefors_p_time'][1], '.3g')} | {val(c['wmw_p_time'], '.2g')} | "
                f"{val(c['wmw_p_iters'], '.2g')} | {val(c['wmw_p_error'], '.2g')} | "
                f"{val(c['cohens_d_time'], '.2f')} | {val(c['cohens_d_iters'], '.2f')} |"
            )
        lines.append("")
    paper = PAPER.get((problem, rho))
    if paper:
        lines += [
            "## The paper's numbers (its own machine and implementation)",
            "",
            "| method | median time (s) | median iters | success | error mean |",
            "|---|---:|---:|---:|---:|",
        ]
        for name, (t, it, sr, e) in paper.items():
            lines.append(f"| {name} (paper) | {t:g} | {it:g} | {sr:.3f} | {e:.2g} |")
        lines.append("")
        lines.append(
            "The paper's \"RIPM\" is Lai & Yoshise's (our `lai-yoshise`); its SO(7) objective is "
            "the literal ½Σ‖log‖_F (`--objective literal`)."
        )
    return "\n".join(lines) + "\n"


def _plots(rows: list[dict], methods: tuple[str, ...], out: Path, problem: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    rates = [np.mean([r["success"] for r in rows if r["method"] == m] or [0.0]) for m in methods]
    axes[0].bar(range(len(methods)), rates, color="tab:blue")
    axes[0].set_xticks(range(len(methods)), methods, rotation=30, ha="right")
    axes[0].set_ylim(0, 1.05)
    axes[0].set_ylabel("success rate")
    its = [[r["iterations"] for r in rows if r["method"] == m] for m in methods]
    times = [[max(r["time_s"], 1e-5) for r in rows if r["method"] == m] for m in methods]
    axes[1].boxplot(its, showfliers=True)
    axes[1].set_xticks(range(1, len(methods) + 1), methods, rotation=30, ha="right")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("iterations (all runs)")
    axes[2].boxplot(times, showfliers=True)
    axes[2].set_xticks(range(1, len(methods) + 1), methods, rotation=30, ha="right")
    axes[2].set_yscale("log")
    axes[2].set_ylabel("wall time [s] (all runs)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"MLG-IPM study on {problem}")
    fig.tight_layout()
    save_plot(fig, out / "study.png", dpi=110)
