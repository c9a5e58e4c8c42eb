"""Validate the maximal-coordinate LGVI (RIPM paper §V.A–B, eq. 27–35) against Pinocchio.

From a seeded random state ``(q₀, v₀)`` two scenarios are simulated for ``T`` seconds at each
``Δt``: passive motion (``τ = 0``, gravity) and constant torques ``τ = g(q₀) + M(q₀) a`` with
``a ~ N(0, 1 rad/s²)``. The LGVI starts from the configurations at ``t = 0`` and ``t = Δt`` of a
fine reference (Pinocchio's ABA, RK4 with 0.1 ms steps), so both initial knots satisfy the joint
constraints exactly. Reported per ``Δt``: the worst joint-angle error against the reference at
the knots, the worst pivot + axis residual of every joint at every knot (Table I rows 5–6), the
relative drift of the discrete energy (eq. 33) in the passive case and the observed order; the
error of an explicit midpoint (RK2) integration of the ABA at the same ``Δt`` calibrates what a
second-order method achieves on the same motion. A long passive run shows bounded energy error
without secular drift.

Non-revolute joints (panda's prismatic fingers) are locked at their neutral position with
``pinocchio.buildReducedModel``: the transcription handles revolute joints only.
Regenerate with ``mbplan validate-dynamics --robot NAME --seed S --out DIR``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from tqdm import tqdm

from mbplan.benchmarks.common import machine_info, save_plot, write_atomic, write_json
from mbplan.errors import InputError, MbplanError
from mbplan.lie import SO3
from mbplan.multibody import MaximalModel, joint_positions, maximal_model
from mbplan.robots import load
from mbplan.simulation import integrate_aba, simulate_maximal

DTS = (0.008, 0.004, 0.002, 0.001)
REFERENCE_STEP = 1e-4  # RK4 step of the Pinocchio reference [s]
LONG_DT = 0.001
LONG_STEPS = 10_000
SCENARIOS = ("passive", "torque")


def revolute_model(robot: str | Path) -> tuple[pin.Model, list[str]]:
    """Pinocchio model of ``robot`` with every non-revolute joint locked at its neutral position.

    Returns the (possibly reduced) model and the names of the locked joints.
    """
    model = load(robot, geometry=False).model
    revolute = ("JointModelR", "JointModelRevolute")
    locked = [
        j for j in range(1, model.njoints) if not model.joints[j].shortname().startswith(revolute)
    ]
    if not locked:
        return model, []
    reduced = pin.buildReducedModel(model, locked, pin.neutral(model))
    return reduced, [model.names[j] for j in locked]


def random_state(
    mm: MaximalModel, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``q₀`` uniform within the joint limits (``[-π, π]`` where unbounded or empty), ``v₀ ~ N(0,
    0.5 rad/s)`` and the torque scenario's ``a ~ N(0, 1 rad/s²)``."""
    model = mm.model
    lo, hi = mm.lower_position_limit, mm.upper_position_limit
    bounded = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    theta = rng.uniform(np.where(bounded, lo, -np.pi), np.where(bounded, hi, np.pi))
    q0 = pin.neutral(model)
    plain = ~mm.continuous
    q0[mm.idx_q[plain]] = theta[plain]
    q0[mm.idx_q[mm.continuous]] = np.cos(theta[mm.continuous])
    q0[mm.idx_q[mm.continuous] + 1] = np.sin(theta[mm.continuous])
    return q0, 0.5 * rng.standard_normal(model.nv), rng.standard_normal(model.nv)


def reference(
    model: pin.Model, q0: np.ndarray, v0: np.ndarray, tau: np.ndarray, h: float, n: int
) -> np.ndarray:
    """Pinocchio ABA + RK4 (steps ≤ :data:`REFERENCE_STEP`) sampled every ``h``: ``(n+1, nq)``."""
    substeps = max(1, math.ceil(h / REFERENCE_STEP - 1e-9))
    qs = np.empty((n + 1, model.nq))
    qs[0] = q = np.asarray(q0, dtype=float)
    v = np.asarray(v0, dtype=float)
    for k in range(n):
        q, v = integrate_aba(model, q, v, tau, h, substeps)
        qs[k + 1] = q
    return qs


def midpoint_aba(
    model: pin.Model, q0: np.ndarray, v0: np.ndarray, tau: np.ndarray, dt: float, N: int
) -> np.ndarray:
    """Baseline of the same order as the LGVI: explicit midpoint (RK2) on Pinocchio's ABA with
    step ``dt``, configurations ``(N+1, nq)``."""
    data = model.createData()
    qs = np.empty((N + 1, model.nq))
    qs[0] = q = np.asarray(q0, dtype=float)
    v = np.asarray(v0, dtype=float)
    for k in range(N):
        v_mid = v + 0.5 * dt * pin.aba(model, data, q, v, tau)
        q_mid = pin.integrate(model, q, 0.5 * dt * v)
        v = v + dt * pin.aba(model, data, q_mid, v_mid, tau)
        q = qs[k + 1] = pin.integrate(model, q, dt * v_mid)
    return qs


def joint_trajectory(mm: MaximalModel, R: np.ndarray, q_start: np.ndarray) -> np.ndarray:
    """Joint configurations ``(K, nq)`` of body orientations ``R`` (K, nb, 3, 3), each angle taken
    in the 2π-window of the previous knot's (continuity from ``q_start``)."""
    out = np.empty((len(R), mm.nq))
    q = q_start
    for k, Rk in enumerate(R):
        q = out[k] = joint_positions(mm, Rk, q_ref=q)
    return out


def joint_errors(mm: MaximalModel, q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Joint-angle differences ``(K, nb)`` (continuous joints via their (cos, sin) pair)."""
    plain = mm.idx_q[~mm.continuous]
    err = np.zeros((len(q), mm.nb))
    err[:, ~mm.continuous] = q[:, plain] - q_ref[:, plain]
    c = mm.idx_q[mm.continuous]
    err[:, mm.continuous] = np.arctan2(
        q[:, c + 1] * q_ref[:, c] - q[:, c] * q_ref[:, c + 1],
        q[:, c] * q_ref[:, c] + q[:, c + 1] * q_ref[:, c + 1],
    )
    return err


def constraint_residuals(mm: MaximalModel, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Worst pivot/axis residual over the joints at each knot (Table I rows 5–6): ``(K,)``.

    Pivot ``R_p r_p + p_p - R_c r_c - p_c``, axis ``(R_p perp_i)ᵀ(R_c axis_c)``, with the world
    (``R = I``, ``p = 0``) as parent of the root joints.
    """
    world = mm.parent < 0
    par = np.maximum(mm.parent, 0)
    Rp = np.where(world[None, :, None, None], np.eye(3), R[:, par])
    pp = np.where(world[None, :, None], 0.0, p[:, par])
    pivot = (
        np.einsum("kbij,bj->kbi", Rp, mm.r_parent)
        + pp
        - np.einsum("kbij,bj->kbi", R, mm.r_child)
        - p
    )
    axis = np.einsum(
        "kbji,bli,kbjm,bm->kbl", Rp, mm.perp_parent, R, mm.axis_child
    )  # (R_p perp_l)·(R_c a)
    return np.maximum(np.abs(pivot).max(axis=(1, 2)), np.abs(axis).max(axis=(1, 2)))


def discrete_energy(
    mm: MaximalModel, p: np.ndarray, F: np.ndarray, v: np.ndarray, dt: float
) -> np.ndarray:
    """Discrete energy of each step ``k → k+1`` (eq. 33): ``(K,)``.

    ``E_k = Σ_b tr((I - F_k) J_b)/Δt² + ½ m_b‖v_k‖² - m_b gᵀ(p_k + p_{k+1})/2``; the rotational
    term equals ``tr((F_k - I) J (F_k - I)ᵀ)/(2Δt²)``, i.e. ``T_d/Δt`` of eq. 33, and tends to
    ``½ ωᵀ I_b ω``.
    """
    rot = np.einsum("kbij,bji->kb", np.eye(3) - F, mm.inertia_nonstandard) / dt**2
    trans = 0.5 * mm.mass * np.einsum("kbi,kbi->kb", v, v)
    mid = p + 0.5 * dt * v  # (p_k + p_{k+1}) / 2 with p_{k+1} = p_k + v_k Δt (eq. 30)
    potential = -mm.mass * np.einsum("kbi,i->kb", mid, mm.gravity)
    return (rot + trans + potential).sum(axis=1)


def _simulate(
    mm: MaximalModel,
    q_ref: np.ndarray,
    v0: np.ndarray,
    h: float,
    tau: np.ndarray,
    dt: float,
    N: int,
) -> dict[str, Any]:
    """One LGVI run at ``dt`` compared with the reference ``q_ref`` sampled every ``h`` (and the
    :func:`midpoint_aba` baseline at the same ``dt``)."""
    stride = round(dt / h)
    q_rk2 = midpoint_aba(mm.model, q_ref[0], v0, tau, dt, N)
    rk2_err = np.abs(joint_errors(mm, q_rk2, q_ref[: N * stride + 1 : stride])).max()
    run: dict[str, Any] = {"dt": dt, "steps": N, "rk2_joint_error_rad": float(rk2_err)}
    try:
        traj = simulate_maximal(mm, q_ref[0], q_ref[stride], tau[mm.idx_v], dt, N)
    except MbplanError as err:
        return run | {"failed": str(err)}
    q = joint_trajectory(mm, traj.R, q_ref[0])
    err = np.abs(joint_errors(mm, q, q_ref[: N * stride + 1 : stride]))
    energy = discrete_energy(mm, traj.p, traj.F, traj.v, dt)
    return run | {
        "max_joint_error_rad": float(err.max()),
        "final_joint_error_rad": float(err[-1].max()),
        "max_constraint_residual": float(constraint_residuals(mm, traj.R, traj.p).max()),
        "energy_drift_rel": float(np.abs(energy - energy[0]).max() / abs(energy[0])),
        "max_rotation_per_step_rad": float(np.linalg.norm(SO3.log(traj.F), axis=-1).max()),
        "max_joint_speed_rad_s": float(np.abs(np.diff(q, axis=0)).max() / dt),
        "max_newton_iterations": int(traj.newton_iterations.max()),
        "max_step_residual": traj.max_residual,
        "energy": energy,
    }


def _long_run(mm: MaximalModel, q0: np.ndarray, v0: np.ndarray, steps: int) -> dict:
    """Passive run of ``steps`` steps at :data:`LONG_DT`: energy error trend vs oscillation."""
    zero = np.zeros(mm.nv)
    q1 = reference(mm.model, q0, v0, zero, LONG_DT, 1)[1]
    head = {"dt": LONG_DT, "steps": steps, "duration_s": LONG_DT * steps}
    try:
        traj = simulate_maximal(mm, q0, q1, zero[mm.idx_v], LONG_DT, steps)
    except MbplanError as err:
        return head | {"failed": str(err)}
    energy = discrete_energy(mm, traj.p, traj.F, traj.v, LONG_DT)
    t = LONG_DT * np.arange(len(energy))
    e = (energy - energy[0]) / abs(energy[0])
    slope, intercept = np.polyfit(t, e, 1)
    detrended = e - (slope * t + intercept)
    return head | {
        "E0_J": float(energy[0]),
        "max_energy_error_J": float(np.abs(energy - energy[0]).max()),
        "max_energy_error_rel": float(np.abs(e).max()),
        "trend_slope_rel_per_s": float(slope),
        "trend_intercept_rel": float(intercept),
        "trend_over_run_rel": float(slope * t[-1]),
        "oscillation_amplitude_rel": float(0.5 * (detrended.max() - detrended.min())),
        "first_half_max_rel": float(np.abs(e[: len(e) // 2]).max()),
        "second_half_max_rel": float(np.abs(e[len(e) // 2 :]).max()),
        "max_constraint_residual": float(constraint_residuals(mm, traj.R, traj.p).max()),
        "energy_error_rel": e,
    }


def _orders(errors: list[float | None], dts: tuple[float, ...]) -> list[float | None]:
    """``log(e_i / e_{i+1}) / log(Δt_i / Δt_{i+1})`` for successive step sizes."""
    out: list[float | None] = []
    for i in range(len(dts) - 1):
        a, b = errors[i], errors[i + 1]
        ok = a is not None and b is not None and a > 0 and b > 0
        out.append(math.log(a / b) / math.log(dts[i] / dts[i + 1]) if ok else None)
    return out


def run(
    robot: str,
    seed: int,
    out: Path,
    dts: tuple[float, ...] = DTS,
    T: float = 1.0,
    long_steps: int = LONG_STEPS,
) -> dict:
    """Validate the LGVI of ``robot`` against Pinocchio; write summary.json, results.md and a plot.

    ``dts`` must be integer multiples of the smallest; ``T`` a multiple of each. ``long_steps``
    (0 to skip) sets the length of the passive energy run at 1 ms.
    """
    dts = tuple(sorted((float(d) for d in dts), reverse=True))
    h = dts[-1]
    n_ref = round(T / h)
    for dt in dts:
        if abs(dt / h - round(dt / h)) > 1e-9 or abs(T / dt - round(T / dt)) > 1e-9:
            raise InputError(f"dt={dt} must divide T={T} and be a multiple of {h}")
    out = Path(out)
    model, locked = revolute_model(robot)
    mm = maximal_model(model)
    rng = np.random.default_rng(seed)
    q0, v0, a = random_state(mm, rng)
    data = model.createData()
    torques = {
        "passive": np.zeros(model.nv),
        "torque": pin.rnea(model, data, q0, np.zeros(model.nv), a),  # g(q₀) + M(q₀) a
    }

    scenarios: dict[str, dict[str, Any]] = {}
    energies: dict[float, np.ndarray] = {}
    total = len(SCENARIOS) * sum(round(T / dt) for dt in dts) + long_steps
    with tqdm(total=total, desc=f"validate {mm.name} (LGVI steps)", unit="step") as bar:
        for name in SCENARIOS:
            tau = torques[name]
            q_ref = reference(model, q0, v0, tau, h, n_ref)
            runs = []
            for dt in dts:
                N = round(T / dt)
                result = _simulate(mm, q_ref, v0, h, tau, dt, N)
                energy = result.pop("energy", None)
                if name == "passive" and energy is not None:
                    energies[dt] = energy
                if name != "passive":
                    result.pop("energy_drift_rel", None)
                runs.append(result)
                bar.update(N)
            errors = [r.get("max_joint_error_rad") for r in runs]
            scenarios[name] = {
                "tau": tau.tolist(),
                "runs": runs,
                "observed_order": _orders(errors, dts),
            }
        long = None
        if long_steps:
            long = _long_run(mm, q0, v0, long_steps)
            bar.update(long_steps)

    def worst(key: str, i: int) -> float | None:
        values = [s["runs"][i].get(key) for s in scenarios.values()]
        return None if any(v is None for v in values) else max(values)

    max_err = [worst("max_joint_error_rad", i) for i in range(len(dts))]
    long_summary = (
        None if long is None else {k: v for k, v in long.items() if k != "energy_error_rel"}
    )
    summary = {
        "robot": mm.name,
        "robot_argument": str(robot),
        "seed": seed,
        "command": f"mbplan validate-dynamics --robot {robot} --seed {seed} --out {out}",
        "locked_joints": locked,
        "note": (
            f"non-revolute joints {locked} locked at their neutral position "
            "(pinocchio.buildReducedModel): the maximal transcription supports revolute joints only"
            if locked
            else "all joints revolute"
        ),
        "T": T,
        "dt": list(dts),
        "max_joint_error_rad": max_err,
        "observed_order": _orders(max_err, dts),
        "rk2_max_joint_error_rad": [worst("rk2_joint_error_rad", i) for i in range(len(dts))],
        "max_constraint_residual": [worst("max_constraint_residual", i) for i in range(len(dts))],
        "energy_drift_rel": [r.get("energy_drift_rel") for r in scenarios["passive"]["runs"]],
        "failed_runs": [
            {"scenario": n, "dt": r["dt"], "error": r["failed"]}
            for n, s in scenarios.items()
            for r in s["runs"]
            if "failed" in r
        ],
        "q0": q0.tolist(),
        "v0": v0.tolist(),
        "reference": f"pinocchio.aba + RK4, step {REFERENCE_STEP} s, sampled at the knots",
        "scenarios": scenarios,
        "long_passive_run": long_summary,
        "machine": machine_info(),
    }
    write_json(out / "summary.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    _plot(summary, energies, long, out / "validate_dynamics.png")
    return summary


def _fmt(x: float | None, spec: str = ".2e") -> str:
    return "—" if x is None else format(x, spec)


def _markdown(s: dict) -> str:
    lines = [
        f"# LGVI (maximal coordinates) vs Pinocchio: {s['robot']}",
        "",
        f"Command: `{s['command']}`  ",
        f"Reference: {s['reference']}; horizon T = {s['T']} s; seed {s['seed']}.  ",
        f"Joints: {s['note']}.",
        "",
        "| scenario | Δt [ms] | max joint error [rad] | order | RK2 (ABA) error [rad] "
        "| max constraint residual | energy drift (rel) | max rotation/step [rad] "
        "| max joint speed [rad/s] | Newton its |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, sc in s["scenarios"].items():
        orders = [None, *sc["observed_order"]]
        for r, order in zip(sc["runs"], orders, strict=True):
            head = f"| {name} | {1e3 * r['dt']:g} "
            if "failed" in r:
                lines.append(
                    head + f"| failed: {r['failed']} || {r['rk2_joint_error_rad']:.2e} |||||"
                )
                continue
            lines.append(
                head + f"| {r['max_joint_error_rad']:.2e} | {_fmt(order, '.2f')} "
                f"| {r['rk2_joint_error_rad']:.2e} | {r['max_constraint_residual']:.1e} | {_fmt(r.get('energy_drift_rel'))} "
                f"| {r['max_rotation_per_step_rad']:.3f} | {r['max_joint_speed_rad_s']:.2f} "
                f"| {r['max_newton_iterations']} |"
            )
    i_1ms = s["dt"].index(0.001) if 0.001 in s["dt"] else None
    if i_1ms is not None:
        e = s["max_joint_error_rad"][i_1ms]
        verdict = "meets" if e is not None and e <= 1e-3 else "misses"
        lines += [
            "",
            f"Worst joint error at Δt = 1 ms over {s['T']} s: {_fmt(e)} rad ({verdict} the 1e-3 rad "
            f"target); explicit midpoint (RK2) on ABA, same order and step: "
            f"{_fmt(s['rk2_max_joint_error_rad'][i_1ms])} rad.",
        ]
    worst_res = max((r for r in s["max_constraint_residual"] if r is not None), default=None)
    lines.append(
        f"Worst joint constraint residual at any knot: {_fmt(worst_res, '.1e')} (target 1e-9)."
    )
    lines.append(
        "Observed order (worst error, successive Δt): "
        + ", ".join(_fmt(o, ".2f") for o in s["observed_order"])
        + "."
    )
    if s["failed_runs"]:
        lines.append(f"Failed runs: {s['failed_runs']}.")
    long = s["long_passive_run"]
    if long and "failed" in long:
        lines += ["", f"Long passive run ({long['steps']} steps at 1 ms) failed: {long['failed']}."]
    elif long:
        lines += [
            "",
            f"Long passive run: {long['steps']} steps at Δt = {1e3 * long['dt']:g} ms "
            f"({long['duration_s']:g} s), E₀ = {long['E0_J']:.3f} J. Energy error: max "
            f"{long['max_energy_error_J']:.2e} J = {long['max_energy_error_rel']:.2e} relative "
            f"(first half {long['first_half_max_rel']:.2e}, second half "
            f"{long['second_half_max_rel']:.2e}); linear trend {long['trend_slope_rel_per_s']:.2e}/s, "
            f"i.e. {long['trend_over_run_rel']:.2e} over the run, against an oscillation amplitude "
            f"of {long['oscillation_amplitude_rel']:.2e}. Constraint residual ≤ "
            f"{long['max_constraint_residual']:.1e}.",
        ]
    return "\n".join(lines) + "\n"


def _plot(s: dict, energies: dict[float, np.ndarray], long: dict | None, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    ax = axes[0]
    dts = np.array(s["dt"])
    for name, style, color in (("passive", "o", "C0"), ("torque", "s", "C1")):
        runs = s["scenarios"][name]["runs"]
        err = [r.get("max_joint_error_rad", np.nan) for r in runs]
        ax.loglog(1e3 * dts, err, style + "-", color=color, label=f"{name}: LGVI")
        rk2 = [r["rk2_joint_error_rad"] for r in runs]
        ax.loglog(1e3 * dts, rk2, style + "--", color=color, alpha=0.4, label=f"{name}: RK2 (ABA)")
    anchor = next((e for e in s["max_joint_error_rad"][::-1] if e is not None), None)
    if anchor is not None:
        ax.loglog(1e3 * dts, anchor * (dts / dts[-1]) ** 2, "k:", label="slope 2")
    ax.set_xticks(1e3 * dts, [f"{1e3 * d:g}" for d in dts])
    ax.minorticks_off()
    ax.set_xlabel("Δt [ms]")
    ax.set_ylabel(f"max joint error over {s['T']} s [rad]")
    ax.set_title(f"{s['robot']}: LGVI vs Pinocchio")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)

    ax = axes[1]
    for dt, energy in energies.items():
        t = dt * np.arange(len(energy))
        ax.plot(t, (energy - energy[0]) / abs(energy[0]), label=f"Δt = {1e3 * dt:g} ms")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("(E_k - E_0) / |E_0|")
    ax.set_title("passive: discrete energy (eq. 33)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)

    ax = axes[2]
    if long is not None and "failed" not in long:
        e = long["energy_error_rel"]
        t = long["dt"] * np.arange(len(e))
        ax.plot(t, e, lw=0.5, label="energy error")
        slope = long["trend_slope_rel_per_s"]
        ax.plot(t, slope * t + long["trend_intercept_rel"], "r--", label=f"trend {slope:.1e}/s")
        ax.legend(fontsize=8)
        ax.set_title(f"passive, {long['steps']} steps at Δt = {1e3 * long['dt']:g} ms")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("(E_k - E_0) / |E_0|")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_plot(fig, path, dpi=120)
