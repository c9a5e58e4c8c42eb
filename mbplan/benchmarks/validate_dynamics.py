"""``mbplan validate-dynamics``: the maximal-coordinate LGVI (RIPM paper §V.A–B, eq. 27–35, 60)
against Pinocchio on a smooth motion (:mod:`mbplan.benchmarks.dynamics_scenario`).

For every robot (names of ``mbplan robots``, URDF and MJCF paths), without and with viscous joint
damping (the URDF's ``<dynamics damping>``, or :data:`SYNTHETIC_DAMPING` on every joint where the
URDF has none), the LGVI runs for ``T`` seconds at each ``Δt`` from the configurations of the
reference at ``t = 0`` and ``t = Δt``. Reported per case: the worst joint error at the knots
(rad, m for prismatic joints) at each ``Δt``, the observed order ``p`` and error constant ``C``
of the least-squares fit ``error ≈ C Δt^p``, and the worst joint constraint residual at any knot.
A mechanism with loop closures (:func:`mechanism`) moves as in
:mod:`mbplan.benchmarks.loop_scenario` against Pinocchio's constrained dynamics, and its closure
residuals count among the constraint residuals.
A floating-base robot flies freely (its base not driven, :mod:`mbplan.benchmarks.dynamics_scenario`)
and reports the drift of its discrete momentum (:func:`~mbplan.simulation.discrete_momentum`).
Targets: ``p = 2 ± 0.2``, error ≤ 1e-3 at Δt = 1 ms, residual ≤ 1e-10, momentum drift ≤ 1e-9.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from tqdm import tqdm

from mbplan.benchmarks.common import machine_info, save_plot, write_atomic, write_json
from mbplan.benchmarks.dynamics_scenario import joint_errors, smooth_scenario
from mbplan.benchmarks.loop_scenario import loop_scenario
from mbplan.errors import InputError, MbplanError
from mbplan.multibody import joint_constraint_residuals, joint_positions, maximal_model
from mbplan.multibody.loops import loop_residuals
from mbplan.robots import Robot, available_robots, load, load_robot
from mbplan.robots.joints import is_floating_root
from mbplan.robots.loops import Loop
from mbplan.simulation import discrete_momentum, simulate_maximal

DTS = (0.008, 0.004, 0.002, 0.001)
DURATION = 0.4  # s
SYNTHETIC_DAMPING = 0.1  # N m s/rad (N s/m) on every joint of a robot whose URDF has none
TARGETS = {
    "order": (1.8, 2.2),
    "error_at_1ms": 1e-3,
    "constraint_residual": 1e-10,
    "momentum_drift": 1e-9,
}


def mechanism(robot: str | Path) -> tuple[pin.Model, tuple[Loop, ...], tuple[str, ...]]:
    """The model of ``robot`` with its loop closures and passive joints: for an MJCF file or a
    mechanism with closures (an MJCF file's ``<equality>``, a named mechanism) those of
    :func:`~mbplan.robots.load_robot`, else the model of :func:`~mbplan.robots.load` alone."""
    suffix = Path(robot).suffix.lower()
    if suffix != ".urdf":  # URDF has no closures: its meshes are not needed
        loaded = load_robot(robot)
        if isinstance(loaded, Robot) and (loaded.loops or suffix in (".xml", ".mjcf")):
            return loaded.model, loaded.loops, loaded.passive
    return load(robot, geometry=False).model, (), ()


def damping_variants(robot: str | Path) -> dict[str, tuple[pin.Model, str]]:
    """``{"undamped": …, "damped": …}``: the model of ``robot`` (:func:`mechanism`) with zero and
    with joint damping, and how the damping was chosen."""
    model = mechanism(robot)[0]
    undamped = model.copy()
    undamped.damping[:] = 0.0
    damped = model.copy()
    if np.any(np.asarray(model.damping) > 0):
        how = f"URDF, {np.min(model.damping):g}–{np.max(model.damping):g}"
    else:
        damped.damping[:] = SYNTHETIC_DAMPING
        if is_floating_root(model, 1):  # a floating base has no joint to damp
            damped.damping[:6] = 0.0
        how = f"synthetic {SYNTHETIC_DAMPING:g}"
    return {"undamped": (undamped, "none"), "damped": (damped, how)}


def _check(dts: tuple[float, ...], T: float) -> tuple[float, ...]:
    dts = tuple(sorted((float(d) for d in dts), reverse=True))
    if len(dts) < 2 or not all(math.isfinite(d) and d > 0 for d in dts):
        raise InputError(f"dts: need at least two finite step sizes > 0, got {dts}")
    if not (math.isfinite(T) and T > 0):
        raise InputError(f"T: must be a finite duration > 0, got {T}")
    h = dts[-1]
    for dt in dts:
        if abs(dt / h - round(dt / h)) > 1e-9 or abs(T / dt - round(T / dt)) > 1e-9:
            raise InputError(f"dt={dt} must divide T={T} and be a multiple of {h}")
    return dts


def validate_case(
    model: pin.Model,
    seed: int,
    dts: tuple[float, ...],
    T: float,
    bar: tqdm | None = None,
    loops: tuple[Loop, ...] = (),
    passive: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One robot with one damping (and its loop closures and passive joints): errors per
    ``Δt``, the fitted order and constant."""
    mm = maximal_model(model, loops)
    scenario = loop_scenario(model, loops, passive, seed) if loops else smooth_scenario(mm, seed)
    h = dts[-1]
    substeps = scenario.reference_step(h)
    q_ref, v_ref = scenario.reference(h, round(T / h), substeps)
    runs = []
    for dt in dts:
        stride, N = round(dt / h), round(T / dt)
        tau = np.array([scenario.torque(k * dt)[mm.idx_v[mm.jointed]] for k in range(N + 1)])
        try:
            traj = simulate_maximal(mm, scenario.q0, q_ref[stride], tau, dt, N)
        except MbplanError as err:
            runs.append({"dt": dt, "failed": str(err)})
            continue
        finally:
            if bar is not None:
                bar.update(N)
        q = joint_positions(mm, traj.R, traj.p, q_ref=scenario.q0)
        err = np.abs(joint_errors(mm, q, q_ref[::stride]))
        euler = np.abs(joint_errors(mm, scenario.euler(dt, N), q_ref[::stride]))
        joints = float(joint_constraint_residuals(mm, traj.R, traj.p).max())
        closures = float(np.abs(loop_residuals(mm.loops, traj.R, traj.p)).max(initial=0.0))
        runs.append(
            {
                "dt": dt,
                "max_joint_error": float(err.max()),
                "euler_max_joint_error": float(euler.max()),
                "max_constraint_residual": max(joints, closures),
                "max_newton_iterations": int(traj.newton_iterations.max()),
            }
            | ({"max_closure_residual": closures} if loops else {})
            | ({"momentum_drift": _momentum_drift(mm, traj, dt)} if mm.free.any() else {})
        )
    ok = [r for r in runs if "failed" not in r]
    order, constant = _fit(ok, "max_joint_error")
    return {
        "joints": _joint_counts(mm),
        **({"loops": [lp.describe() for lp in loops]} if loops else {}),
        "max_damping_rate_per_s": float(
            np.max(
                np.asarray(model.damping)
                / np.diag(pin.crba(model, model.createData(), scenario.q0))
            )
        ),
        "max_speed_rad_s": float(np.abs(v_ref).max()),
        "reference_step_s": h / substeps,
        "runs": runs,
        "observed_order": order,
        "error_constant": constant,
        "euler_observed_order": _fit(ok, "euler_max_joint_error")[0],
    }


def _fit(runs: list[dict[str, Any]], key: str) -> tuple[float | None, float | None]:
    """``(p, C)`` of the least-squares fit ``log e = log C + p log Δt``."""
    if len(runs) < 2:
        return None, None
    x, y = np.log([r["dt"] for r in runs]), np.log([r[key] for r in runs])
    slope, intercept = np.polyfit(x, y, 1)
    return float(slope), float(np.exp(intercept))


def _joint_counts(mm) -> dict[str, int]:
    """Joints per kind, continuous (unbounded revolute) joints counted apart."""
    kinds = ["continuous" if c else t for t, c in zip(mm.joint_types, mm.continuous, strict=True)]
    return {
        k: kinds.count(k) for k in ("revolute", "continuous", "prismatic", "free") if k in kinds
    }


def _momentum_drift(mm, traj, dt: float) -> float:
    """Largest change of the discrete linear or angular momentum (gravity's impulses taken
    out, :func:`~mbplan.simulation.discrete_momentum`) relative to the largest momentum of the
    run (``Σ m|v|``, ``Σ m|p × v|``): a floating robot in free flight keeps both (its joint
    forces are internal)."""
    speed = np.linalg.norm(traj.v, axis=-1)
    moment = np.linalg.norm(np.cross(traj.p, traj.v), axis=-1)
    scales = (float((speed @ mm.mass).max()), float((moment @ mm.mass).max()))
    drifts = []
    for momentum, scale in zip(discrete_momentum(mm, traj, dt), scales, strict=True):
        drifts.append(float(np.abs(momentum - momentum[0]).max()) / max(scale, 1e-300))
    return max(drifts)


def _verdict(case: dict[str, Any], dts: tuple[float, ...]) -> list[str]:
    """Targets a case misses (empty: all met)."""
    lo, hi = TARGETS["order"]
    missed = []
    if any("failed" in r for r in case["runs"]):
        missed.append("a run failed")
    if case["observed_order"] is None or not lo <= case["observed_order"] <= hi:
        missed.append("order")
    at_1ms = [r for r in case["runs"] if abs(r["dt"] - 1e-3) < 1e-12 and "failed" not in r]
    if 1e-3 in dts and (not at_1ms or at_1ms[0]["max_joint_error"] > TARGETS["error_at_1ms"]):
        missed.append("error at 1 ms")
    residuals = [r["max_constraint_residual"] for r in case["runs"] if "failed" not in r]
    if not residuals or max(residuals) > TARGETS["constraint_residual"]:
        missed.append("constraint residual")
    drifts = [r["momentum_drift"] for r in case["runs"] if "momentum_drift" in r]
    if drifts and max(drifts) > TARGETS["momentum_drift"]:
        missed.append("momentum")
    return missed


def run(
    robots: tuple[str, ...] | None,
    seed: int,
    out: Path,
    dts: tuple[float, ...] = DTS,
    T: float = DURATION,
) -> dict[str, Any]:
    """Validate every robot of ``robots`` (default: every robot of ``mbplan robots``)
    without and with damping; write results.json, results.md and validate_dynamics.png into
    ``out``."""
    dts = _check(dts, T)
    names = tuple(robots) if robots else tuple(available_robots())
    variants = {name: damping_variants(name) for name in names}  # bad robots fail here, first
    closures = {name: mechanism(name)[1:] for name in names}
    for name, v in variants.items():
        maximal_model(v["undamped"][0], closures[name][0])  # unsupported joints: before any run
    cases = []
    total = 2 * len(names) * sum(round(T / dt) for dt in dts)
    with tqdm(total=total, desc="validate-dynamics (LGVI steps)", unit="step") as bar:
        for name, v in variants.items():
            for label, (model, how) in v.items():
                bar.set_postfix_str(f"{name}, {label}")
                case = validate_case(model, seed, dts, T, bar, *closures[name])
                case |= {"robot": name, "damping": label, "damping_source": how}
                case["missed"] = _verdict(case, dts)
                cases.append(case)
    robot_args = "" if robots is None else f" --robot {','.join(names)}"
    summary = {
        "command": f"mbplan validate-dynamics{robot_args} --seed {seed} --duration {T:g} --out {out}",
        "seed": seed,
        "T": T,
        "dt": list(dts),
        "targets": TARGETS,
        "synthetic_damping": SYNTHETIC_DAMPING,
        "all_targets_met": all(not c["missed"] for c in cases),
        "cases": cases,
        "machine": machine_info(),
    }
    out = Path(out)
    write_json(out / "results.json", summary)
    write_atomic(out / "results.md", _markdown(summary))
    _plot(summary, out / "validate_dynamics.png")
    return summary


def _fmt(x: float | None, spec: str = ".2e") -> str:
    return "—" if x is None else format(x, spec)


def _markdown(s: dict[str, Any]) -> str:
    dts = s["dt"]
    lo, hi = s["targets"]["order"]
    lines = [
        "# LGVI (maximal coordinates) vs Pinocchio on a smooth motion",
        "",
        f"Command: `{s['command']}`  ",
        f"Scenario: `mbplan.benchmarks.dynamics_scenario` (from rest, smooth torques, T = {s['T']} s,"
        f" seed {s['seed']}); reference RK4 on ABA with damping at ≤ Δt_min/16.  ",
        f"Targets: order {lo}–{hi}, error at Δt = 1 ms ≤ {s['targets']['error_at_1ms']:g}, "
        f"constraint residual ≤ {s['targets']['constraint_residual']:g}, momentum drift (floating "
        f"base, relative to the run's largest momentum) ≤ "
        f"{s['targets'].get('momentum_drift', float('nan')):g}. "
        f"All met: **{'yes' if s['all_targets_met'] else 'no'}**.",
        "",
        "| robot | joints | damping | c/M max [1/s] | max speed [rad/s] | "
        + " | ".join(f"error @ {1e3 * d:g} ms" for d in dts)
        + " | order p | C [Δt^-p] | constraint residual | momentum drift | Euler order | targets |",
        "|---|---|---|---:|---:|" + "---:|" * len(dts) + "---:|---:|---:|---:|---:|---|",
    ]
    for c in s["cases"]:
        errors = [
            _fmt(r.get("max_joint_error")) if "failed" not in r else "failed" for r in c["runs"]
        ]
        residuals = [r["max_constraint_residual"] for r in c["runs"] if "failed" not in r]
        drifts = [r["momentum_drift"] for r in c["runs"] if "momentum_drift" in r]
        joints = ", ".join(f"{n} {k}" for k, n in c["joints"].items())
        lines.append(
            f"| {c['robot']} | {joints} | {c['damping_source']} | {c['max_damping_rate_per_s']:.3g} "
            f"| {c['max_speed_rad_s']:.2f} | "
            + " | ".join(errors)
            + f" | {_fmt(c['observed_order'], '.2f')} | {_fmt(c['error_constant'], '.2g')} "
            f"| {_fmt(max(residuals, default=None), '.1e')} "
            f"| {_fmt(max(drifts, default=None), '.1e')} "
            f"| {_fmt(c['euler_observed_order'], '.2f')} "
            f"| {'met' if not c['missed'] else 'missed: ' + ', '.join(c['missed'])} |"
        )
    lines += [
        "",
        "Errors are the worst joint error over the knots (rad; m for prismatic joints). "
        "`c/M max` is the largest damping rate c_i/M_ii(q₀) (stiffness of the damped motion). "
        "`Euler order`: the fitted order of semi-implicit Euler on the damped ABA in the same "
        "scenario, a first-order method the check tells apart. Mechanisms with loop closures "
        "(their names listed below) run the scenario of `mbplan.benchmarks.loop_scenario` against "
        "Pinocchio's constrained dynamics; their constraint residual includes the closures'.",
        *(
            f"- {c['robot']}: {'; '.join(c['loops'])}"
            for c in s["cases"]
            if c.get("loops") and c["damping"] == "undamped"
        ),
    ]
    return "\n".join(lines) + "\n"


def _plot(s: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    dts = np.array(s["dt"])
    for ax, label in zip(axes, ("undamped", "damped"), strict=True):
        for c in (c for c in s["cases"] if c["damping"] == label):
            err = [r.get("max_joint_error", np.nan) for r in c["runs"]]
            ax.loglog(1e3 * dts, err, "o-", lw=1, ms=3, label=c["robot"])
        ax.loglog(1e3 * dts, 1e-3 * (dts / 1e-3) ** 2, "k:", lw=2, label="slope 2")
        ax.set_xticks(1e3 * dts, [f"{1e3 * d:g}" for d in dts])
        ax.minorticks_off()
        ax.set_xlabel("Δt [ms]")
        ax.set_title(f"LGVI vs Pinocchio, {label}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel(f"max joint error over {s['T']} s")
    axes[1].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_plot(fig, path, dpi=120)
