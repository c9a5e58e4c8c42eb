"""Cost of the multi-body LGVI transcription against the number of bodies (RIPM paper §VI.C, Fig. 6).

A serial chain of ``n`` identical links (revolute joints, axes alternating x/y) is transcribed
over ``N`` steps with :func:`mbplan.transcription.multibody.multibody_layout`; at a feasible
point (warm start from a smooth joint trajectory, :func:`maximal_warm_start`) we time the
0th order (residuals), the 1st order (+ Riemannian Jacobian) and the 2nd order (+ Hessian of the
Lagrangian) of the whole NLP. Linear complexity in the bodies means a time ratio ≈ 64 between
64 bodies and 1 body (less when a fixed per-call overhead dominates at 1 body).
Regenerate with ``mbplan bench chain --out DIR``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
from tqdm import tqdm

from mbplan.benchmarks.common import machine_info, median_time, save_plot, write_atomic, write_json
from mbplan.multibody import maximal_model
from mbplan.simulation.warm_start import maximal_warm_start
from mbplan.transcription.multibody import multibody_layout
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import TrajectoryVariables

BODIES = (1, 2, 4, 8, 16, 32, 64)
ORDERS = ("value", "jacobian", "hessian")
LINK_LENGTH = 0.25  # m
LINK_MASS = 1.0  # kg
LINK_RADIUS = 0.03  # m (solid cylinder)


def chain_model(n: int) -> pin.Model:
    """Serial chain of ``n`` identical cylinders, revolute joints about x, y, x, … at their ends."""
    model = pin.Model()
    model.name = f"chain{n}"
    L, m, r = LINK_LENGTH, LINK_MASS, LINK_RADIUS
    inertia = pin.Inertia(
        m,
        np.array([0.0, 0.0, L / 2]),
        np.diag([m * (3 * r**2 + L**2) / 12, m * (3 * r**2 + L**2) / 12, m * r**2 / 2]),
    )
    parent = 0
    for i in range(n):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, L if i else 0.0]))
        joint = pin.JointModelRX() if i % 2 == 0 else pin.JointModelRY()
        parent = model.addJoint(
            parent,
            joint,
            placement,
            f"joint{i + 1}",
            np.array([50.0]),
            np.array([10.0]),
            np.array([-np.pi]),
            np.array([np.pi]),
        )
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    return model


def chain_problem(
    n: int, N: int, dt: float, seed: int
) -> tuple[TrajectoryProblem, dict, np.ndarray]:
    """The transcription of the ``n``-link chain, a feasible point and random multipliers ``y``."""
    mm = maximal_model(chain_model(n))
    rng = np.random.default_rng(seed)
    t = dt * np.arange(N + 2)[:, None]
    q = rng.uniform(-1.0, 1.0, n) + 0.5 * np.sin(2.0 * t + rng.uniform(0, 2 * np.pi, n))
    layout = multibody_layout(mm, N, dt, jit=True)
    problem = TrajectoryProblem(TrajectoryVariables(layout.blocks), layout.terms)
    point = problem.check_point(maximal_warm_start(mm, q, dt, N=N, jit=True))
    return problem, point, rng.standard_normal(problem.n_eq)


def run(
    out: Path, bodies: tuple[int, ...] = BODIES, N: int = 40, dt: float = 0.01, seed: int = 0
) -> dict:
    """Time the 0th/1st/2nd-order evaluation for each chain length; write summary.json,
    results.md and chain_scaling.png under ``out``."""
    out = Path(out)
    rows = []
    for n in tqdm(bodies, desc="chain scaling (bodies)"):
        problem, point, y = chain_problem(n, N, dt, seed)
        feasibility = float(np.abs(problem.values(point)[1]).max())
        rows.append(
            {
                "bodies": n,
                "variables": problem.n,
                "equations": problem.n_eq,
                "max_residual_at_point": feasibility,
                "value_s": median_time(lambda p=problem, x=point: p.values(x)),
                "jacobian_s": median_time(lambda p=problem, x=point: p.evaluate(x, hessian=False)),
                "hessian_s": median_time(lambda p=problem, x=point, y=y: p.evaluate(x, y=y)),
            }
        )
    summary = {
        "benchmark": "multi-body LGVI transcription: evaluation time vs bodies (paper Fig. 6)",
        "command": f"mbplan bench chain --out {out}",
        "N": N,
        "dt": dt,
        "seed": seed,
        "chain": f"{LINK_LENGTH} m, {LINK_MASS} kg cylinders, revolute joints alternating x/y",
        "machine": machine_info(),
        "rows": rows,
    }
    first, last = rows[0], rows[-1]
    summary["ratio_last_over_first"] = {
        "bodies": [first["bodies"], last["bodies"]],
        **{o: last[f"{o}_s"] / first[f"{o}_s"] for o in ORDERS},
    }
    big = [r for r in rows if r["bodies"] >= 8]
    if len(big) >= 2:
        x = np.log([r["bodies"] for r in big])
        summary["loglog_slope_from_8_bodies"] = {
            o: float(np.polyfit(x, np.log([r[f"{o}_s"] for r in big]), 1)[0]) for o in ORDERS
        }
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    _plot(rows, N, out / "chain_scaling.png")
    return summary


def _markdown(s: dict) -> str:
    ratio = s["ratio_last_over_first"]
    n0, n1 = ratio["bodies"]
    lines = [
        "# Multi-body LGVI transcription: evaluation time vs number of bodies (Fig. 6)",
        "",
        f"Command: `{s['command']}`  ",
        f"Chain: {s['chain']}; N = {s['N']} steps, Δt = {s['dt']} s; JIT-compiled terms.  ",
        f"Machine: {s['machine']['processor']}, {s['machine']['cpus']} CPUs, "
        f"CasADi {s['machine']['casadi']}",
        "",
        "| bodies | variables | equations | 0th order [ms] | 1st order [ms] | 2nd order [ms] | 2nd order per body [ms] |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in s["rows"]:
        lines.append(
            f"| {r['bodies']} | {r['variables']} | {r['equations']} | {1e3 * r['value_s']:.3f} "
            f"| {1e3 * r['jacobian_s']:.3f} | {1e3 * r['hessian_s']:.3f} "
            f"| {1e3 * r['hessian_s'] / r['bodies']:.3f} |"
        )
    lines += [
        "",
        f"Time ratio {n1} bodies / {n0} body: "
        + ", ".join(f"{o} {ratio[o]:.1f}×" for o in ORDERS)
        + f" (linear: {n1 / n0:g}×, target ≤ 70×).",
    ]
    if "loglog_slope_from_8_bodies" in s:
        slopes = s["loglog_slope_from_8_bodies"]
        lines.append(
            "Log-log slope from 8 bodies on: "
            + ", ".join(f"{o} {slopes[o]:.2f}" for o in ORDERS)
            + " (linear: 1)."
        )
    worst = max(r["max_residual_at_point"] for r in s["rows"])
    lines.append(f"Evaluation point: warm start, max equality residual {worst:.1e}.")
    return "\n".join(lines) + "\n"


def _plot(rows: list[dict], N: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([r["bodies"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 4))
    for order, label, style in zip(
        ORDERS, ("0th order", "1st order", "2nd order"), ("o-", "s-", "^-"), strict=True
    ):
        ax.loglog(n, [r[f"{order}_s"] for r in rows], style, label=label)
    ax.loglog(n, rows[-1]["hessian_s"] * n / n[-1], "k:", label="linear")
    ax.set_xlabel("bodies in the chain")
    ax.set_ylabel("time per evaluation [s]")
    ax.set_title(f"Multi-body LGVI transcription, N = {N} steps")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_plot(fig, path, dpi=120)
