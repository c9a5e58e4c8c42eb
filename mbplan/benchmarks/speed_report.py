"""The speed benchmark's report (:mod:`mbplan.benchmarks.speed`): results.md from its
summary, every median and ratio with its bootstrap interval, and the chain-size plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

INTERVALS = {
    "kind": "paired percentile bootstrap over the cases",
    "level": 0.95,
    "draws": 2000,
    "seed": 0,
}
"""How the speed benchmark draws its intervals (stored in summary.json, named in results.md)."""


def baseline(task: str) -> str:
    """The method every other one of a task is compared with."""
    return "ipopt" if task.startswith("iiwa") else "ipopt-quaternion"


def _ratio(a: float | None, b: float | None) -> str:
    return within(quotient(a, b), None)


def fmt(v: float | None, scale: float = 1.0, digits: int = 1) -> str:
    """``scale * v`` with ``digits`` decimals, ``—`` for ``None``."""
    return "—" if v is None else f"{scale * v:.{digits}f}"


def within(value: float | None, interval: tuple[float, float] | None, scale: float = 1.0) -> str:
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


def quotient(a: float | None, b: float | None) -> float | None:
    """``a / b``, ``None`` if either is missing or ``b`` is zero."""
    return None if a is None or b is None or b == 0 else a / b


_ORDERS = ("amd", "metis", "nested", "grid-nd", "time-major", "stage-dense", "body-major")


def markdown(s: dict) -> str:
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
        base = baseline(task)
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
                within(quotient(m[key], b.get(key)), c.get(f"{what}_ratio"))
                for key, what in (
                    ("median_total_time_s", "total"),
                    ("median_solve_time_s", "solve"),
                    ("median_time_per_iter_s", "time_per_iter"),
                )
            )
            total, solve, per_iter = ratios
            lines.append(
                f"| {name} | {m['verified']}/{m['n']} | {m['converged']}/{m['n']} "
                f"| {fmt(m['median_iters'])} "
                f"| {within(m['median_time_per_iter_s'], c.get('time_per_iter_s'), 1e3)} "
                f"| {fmt(m['median_total_time_s'], 1e3)} | {total} "
                f"| {fmt(m.get('median_solve_time_s'), 1e3)} | {solve} | {per_iter} |"
            )
        lines += ["", "Statuses: " + "; ".join(f"{n}: {m['statuses']}" for n, m in ms.items()), ""]
    for task, title in (
        ("chain", "Chain reach (N = 40, no obstacles)"),
        ("chain-obstacle", "Chain reach around a cylinder (N = 40, eq. 62, joint speed limits)"),
    ):
        if task in s["tasks"]:
            lines += _chain_table(s["tasks"][task], title)
    if "cold" in s:
        lines += _cold_table(s["cold"])
    if "profile" not in s:  # a run of the cold section alone (`--cold-only`)
        return "\n".join(lines) + "\n"
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


def _cold_table(cold: dict) -> list[str]:
    """The ``cold`` section (:mod:`mbplan.benchmarks.cold_start`)."""
    lines = [
        "## Cold start: the plan in a new process (disk caches warm) beside the same plan warm",
        "",
        "Medians over new processes (`python -m mbplan.benchmarks.cold_start TASK METHOD`, one "
        "discarded first), each planning the task twice: *process* is its wall time, *startup* "
        "what it spends besides the two plans (interpreter, imports, exit); *cold* is the first "
        "plan (loading the compiled kernels, *kernels*, and the structures kept on disk), "
        "*warm* the second (everything in memory). A plan is `mbplan.plan`'s wall time, a solve "
        "the solver's own.",
        "",
        "| task | method | process [s] | startup [s] | cold plan [s] | kernels [s] "
        "| cold solve [s] | warm plan [s] | warm solve [s] | cold / warm plan |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for task, methods in cold.items():
        for method, c in methods.items():
            lines.append(
                f"| {task} | {method} | {c['process_s']:.2f} | {c['startup_s']:.2f} "
                f"| {c['cold_plan_s']:.2f} | {c['cold_compile_s']:.2f} | {c['cold_solve_s']:.2f} "
                f"| {c['warm_plan_s']:.2f} | {c['warm_solve_s']:.2f} "
                f"| {_ratio(c['cold_plan_s'], c['warm_plan_s'])} |"
            )
    return [*lines, ""]


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
            f"| {k} | {fmt(r['median_iters'], digits=0)} "
            f"| {fmt(r['median_time_per_iter_s'], 1e3)} | {fmt(i['median_iters'], digits=0)} "
            f"| {fmt(i['median_time_per_iter_s'], 1e3)} | {fmt(r['median_total_time_s'], digits=2)} "
            f"| {fmt(i['median_total_time_s'], digits=2)} "
            f"| {_ratio(r['median_total_time_s'], i['median_total_time_s'])} "
            f"| {r['verified']} / {i['verified']} |"
        )
    return [*lines, ""]


def chain_plot(s: dict, links: tuple[int, ...], out: Path) -> None:
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
