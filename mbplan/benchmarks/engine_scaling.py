"""Engine benchmark: value + Jacobian + Hessian of the rigid-body LGVI step over many knots.

Interpreted CasADi (SX virtual machine) against JIT-compiled C, both mapped over ``K`` knots in
one call. Regenerate with ``mbplan bench engine --out benchmarks/results/engine``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from mbplan.benchmarks.common import machine_info, median_time, save_plot, write_atomic, write_json
from mbplan.dynamics import quadrotor_step
from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import nonstandard_inertia

KNOTS = (1, 10, 100, 1000, 10000)


def rigid_body_step_function(jit: bool) -> RiemannianFunction:
    variables = [
        ("R0", SO3),
        ("R1", SO3),
        ("F0", SO3),
        ("F1", SO3),
        ("p0", R(3)),
        ("p1", R(3)),
        ("v0", R(3)),
        ("v1", R(3)),
        ("u", R(4)),
    ]
    parameters = [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1)]
    return RiemannianFunction("rigid_body_step", variables, quadrotor_step, parameters, jit=jit)


def random_knots(K: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out = {name: SO3.exp(rng.standard_normal((K, 3))) for name in ("R0", "R1", "F0", "F1")}
    out |= {name: rng.standard_normal((K, 3)) for name in ("p0", "p1", "v0", "v1")}
    out["u"] = rng.standard_normal((K, 4))
    return out


def run(out: Path, knots: tuple[int, ...] = KNOTS, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    params = {
        "J": nonstandard_inertia(np.diag([0.01, 0.012, 0.02])),
        "mass": 1.0,
        "gravity": np.array([0.0, 0.0, -9.81]),
        "dt": 0.05,
    }
    functions = {
        "interpreted": rigid_body_step_function(False),
        "jit": rigid_body_step_function(True),
    }
    rows = []
    for K in tqdm(knots, desc="engine benchmark (knots)"):
        x = random_knots(K, rng)
        lam = rng.standard_normal((K, 12))
        row = {"knots": K}
        for label, f in functions.items():
            row[f"{label}_value_s"] = median_time(lambda f=f, x=x: f.value(x, params))
            row[f"{label}_all_s"] = median_time(lambda f=f, x=x, lam=lam: f.hessian(x, params, lam))
        rows.append(row)

    by_k = {r["knots"]: r for r in rows}
    summary = {
        "benchmark": "engine: rigid-body LGVI step residual (12 rows, 30 tangent dims)",
        "command": f"mbplan bench engine --out {out}",
        "machine": machine_info(),
        "rows": rows,
    }
    if 1000 in by_k:
        r = by_k[1000]
        summary["jit_speedup_at_1000"] = r["interpreted_all_s"] / r["jit_all_s"]
    if 1000 in by_k and 10000 in by_k:
        summary["jit_ratio_10000_over_1000"] = by_k[10000]["jit_all_s"] / by_k[1000]["jit_all_s"]
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    _plot(rows, out / "engine_scaling.png")
    return summary


def _markdown(summary: dict) -> str:
    lines = [
        "# Engine benchmark: value + Jacobian + Hessian of the rigid-body LGVI step",
        "",
        f"Command: `{summary['command']}`  ",
        f"Machine: {summary['machine']['processor']}, {summary['machine']['cpus']} CPUs, "
        f"CasADi {summary['machine']['casadi']}",
        "",
        "| knots | interpreted value [ms] | interpreted all [ms] | JIT value [ms] | JIT all [ms] | JIT speed-up (all) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in summary["rows"]:
        lines.append(
            f"| {r['knots']} | {1e3 * r['interpreted_value_s']:.3f} | {1e3 * r['interpreted_all_s']:.3f} "
            f"| {1e3 * r['jit_value_s']:.3f} | {1e3 * r['jit_all_s']:.3f} "
            f"| {r['interpreted_all_s'] / r['jit_all_s']:.1f}× |"
        )
    if "jit_speedup_at_1000" in summary:
        lines += ["", f"JIT speed-up at 10³ knots: {summary['jit_speedup_at_1000']:.1f}×."]
    if "jit_ratio_10000_over_1000" in summary:
        lines.append(
            f"JIT time at 10⁴ knots / 10³ knots: {summary['jit_ratio_10000_over_1000']:.1f} (linear: 10)."
        )
    return "\n".join(lines) + "\n"


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    K = np.array([r["knots"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, style in (("interpreted", "o-"), ("jit", "s-")):
        ax.loglog(K, [r[f"{label}_all_s"] for r in rows], style, label=f"{label}: value+Jac+Hess")
        ax.loglog(
            K, [r[f"{label}_value_s"] for r in rows], style, alpha=0.4, label=f"{label}: value"
        )
    ax.loglog(K, rows[-1]["jit_all_s"] * K / K[-1], "k:", label="linear")
    ax.set_xlabel("knots K (one vectorised call)")
    ax.set_ylabel("time [s]")
    ax.set_title("Rigid-body LGVI step: engine evaluation time")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_plot(fig, path, dpi=120)
