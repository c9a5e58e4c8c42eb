"""Independent check of a planned trajectory against Pinocchio's continuous-time dynamics.

:func:`verify` integrates the robot's equations of motion (``pinocchio.aba``, RK4 with
:data:`SUBSTEPS` steps per interval, :func:`mbplan.simulation.reference.integrate_aba`) under the
planned torques, and measures how far the plan is from that motion, from the obstacles, from the
goal and from the torque limits. It shares no code with the planners' transcriptions.

Torques are replayed as each transcription applies them. Eq. (61) holds ``τ_k`` over
``[t_k, t_{k+1}]`` (zero-order hold). The LGVI applies forces at the knots with trapezoidal
weights (eq. 29): its step ``q_{k+1} = q_k + Δt v_k + ½Δt² q̈_k`` sees ``τ_k`` only, and
``v_{k+1} - v_k = ½Δt (q̈_k + q̈_{k+1})``. Its plans carry ``tau_knots``, replayed by linear
interpolation (first-order hold), which leaves the LGVI's own local error ``⅙Δt²|q̈_k - q̈_{k+1}|``
in ``q``; the interval mean held instead adds ``¼Δt²|q̈_k - q̈_{k+1}|``, a first-order error where
the torque turns quickly (the launch at knot 1, leaving a velocity limit): with it, 17 of 97
converged RIPM plans of the iiwa benchmark failed the deviation ratios (up to 1.86), with linear
interpolation 1 does (1.002), and the median ratio drops from 0.74 to 0.56.

Replay from the planned knots, not open loop. An open-loop replay from ``(q0, v0)`` over the
whole horizon cannot be thresholded for the iiwa: errors grow about 100-fold per 0.3 s (the light
wrist, 1e-3 kg m², is open-loop unstable; RK4 replays of the same torques with 10 and 40
substeps per 75 ms interval differ by more than 1 rad after 1.5 s), so even an exact solution of
eq. (61) departs from its own replay by tens of radians (70 rad for the test's PD rollout). The
pass/fail check therefore replays each interval from the planned state ``(q_k, v_k)``
(multiple-shooting defects); the open-loop deviation is still reported, for information.

Thresholds (all documented values are checked by ``tests/test_verification.py``):

* ``max_joint_deviation_rad`` / ``max_velocity_deviation`` — the largest difference between the
  replayed and planned ``(q_{k+1}, v_{k+1})``. The transcriptions are first order (eq. 61,
  explicit Euler: local errors ``½Δt²|q̈|`` in ``q`` and ``½Δt²|d q̈/dt|`` in ``v``) or better
  (the LGVI), so the threshold is *computed* for each knot, trajectory and Δt: the explicit-Euler
  step ``(q_k + Δt v_k, v_k + Δt·aba(q_k, v_k, τ_k))`` is an exactly known solution of eq. (61),
  and its distance ``e_k`` to the replay is the discretisation error of a first-order scheme
  there. Any transcription at least as accurate stays within ``e_k`` of the replay; knot
  ``k+1`` passes if its deviation is at most ``2 e_k`` (the planner's and the reference
  scheme's errors may add up) plus :data:`DEVIATION_FLOOR` for the solver tolerance.
  ``joint_deviation_ratio``/``velocity_deviation_ratio`` are the largest deviation/threshold
  ratios (≤ 1 passes; an exact eq.-(61) solution has 0.5). The Euler step uses the interval's
  mean torque ``result.tau[k]`` also under linear interpolation (explicit Euler with the control
  sampled at mid-interval, still first order). The larger of the explicit and semi-implicit
  Euler errors as ``e_k`` would only loosen the ``q`` row (same ``v`` step) and does not address
  the LGVI's failures above (it passes 8 of the 17, none of those failing the ``v`` row); it
  is not used. The thresholds are per knot because
  the Euler error varies by orders of magnitude along a trajectory: with one global threshold,
  torques whose gravity part is 2 % off would pass (ratio 0.78); per knot, their velocity ratio
  exceeds 4 (the ``q`` row alone cannot see torque errors: ``q_{k+1} = q_k + Δt v_k`` does not
  involve ``τ``).
* ``min_obstacle_distance_m`` ≥ 0 — the smallest clearance over all RK4 substeps of the
  replayed intervals: eq. (62) COM-to-axis distance minus the radius (without the task's margin,
  which exists to absorb the inter-knot motion), and, for general :class:`Obstacle` s, the coal
  distance between the robot's collision geometry and the obstacle (for
  ``obstacle_constraint = "distance"`` tasks: of every obstacle, cylinders as finite solids).
* ``final_goal_error_rad`` ≤ ``task.goal_tolerance`` — ``‖q(T) - q_target‖_∞`` at the end of
  the replayed last interval (the tracking cost is soft, so a plan that converged to a local
  minimum blocked by the obstacle fails here).
* ``torque_limit_violation`` ≤ :data:`TORQUE_TOLERANCE` ``· max(1, limit)`` — the largest
  ``|τ_k| - limit`` (N m; over ``tau_knots`` when given), relative to the solvers' tolerance 1e-6.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from mbplan.errors import InputError
from mbplan.results import PlanResult
from mbplan.simulation.reference import integrate_aba
from mbplan.tasks.obstacle import (
    Obstacle,
    ObstacleTask,
    com_clearances,
    geometry_distances,
    link_coms,
    robot_description,
)

SUBSTEPS = 20  # RK4 steps per interval: at Δt = 0.075 s, 20 and 40 agree to < 1e-8 rad
DEVIATION_FLOOR = 1e-5  # rad and rad/s: IPOPT's tolerance on the eq. (61) rows, after Δt scaling
TORQUE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Verification:
    """Outcome of :func:`verify` (module docstring for the metrics and thresholds)."""

    max_joint_deviation_rad: float
    min_obstacle_distance_m: float
    final_goal_error_rad: float
    torque_limit_violation: float
    passed: bool
    reasons: list[str] = field(default_factory=list)
    max_velocity_deviation: float = float("nan")
    joint_deviation_ratio: float = float("nan")
    velocity_deviation_ratio: float = float("nan")
    open_loop_deviation_rad: float = float("nan")


def _interval_replays(
    task: ObstacleTask, result: PlanResult
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RK4 replay of every interval from the planned knot: substep configurations
    ``(N, SUBSTEPS+1, nq)`` and end states ``q, v (N, nq)``."""
    model = robot_description(task.robot).model
    h = task.dt / SUBSTEPS
    path = np.empty((task.N, SUBSTEPS + 1, model.nq))
    v_end = np.empty((task.N, model.nv))
    for k in range(task.N):
        q, v = result.q[k], result.v[k]
        path[k, 0] = q
        for s in range(SUBSTEPS):
            q, v = _replay_step(model, q, v, result, k, s * h, h)
            path[k, s + 1] = q
        v_end[k] = v
    return path, path[:, -1], v_end


def _replay_step(
    model: pin.Model, q: np.ndarray, v: np.ndarray, result: PlanResult, k: int, t: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """RK4 over ``[t_k + t, t_k + t + h]`` under the plan's torque: ``τ_k`` held, or the linear
    ramp between ``tau_knots[k]`` and ``tau_knots[k+1]`` when the plan has knot torques."""
    if result.tau_knots is None:
        return integrate_aba(model, q, v, result.tau[k], h, 1)
    a, b = result.tau_knots[k], result.tau_knots[k + 1]
    s0, s1 = t / result.dt, (t + h) / result.dt
    return integrate_aba(model, q, v, a + s0 * (b - a), h, 1, tau_end=a + s1 * (b - a))


def _euler_steps(task: ObstacleTask, result: PlanResult) -> tuple[np.ndarray, np.ndarray]:
    """One explicit-Euler step of eq. (61) from each planned knot: ``q, v (N, nq)``."""
    model = robot_description(task.robot).model
    data = model.createData()
    q, v, dt = result.q[:-1], result.v[:-1], task.dt
    acc = np.array([pin.aba(model, data, q[k], v[k], result.tau[k]) for k in range(task.N)])
    return q + dt * v, v + dt * acc


def _open_loop_deviation(task: ObstacleTask, result: PlanResult) -> float:
    model = robot_description(task.robot).model
    q, v = task.q0, np.zeros(model.nv)
    deviation = 0.0
    h = task.dt / SUBSTEPS
    for k in range(task.N):
        for s in range(SUBSTEPS):
            q, v = _replay_step(model, q, v, result, k, s * h, h)
        deviation = max(deviation, float(np.max(np.abs(q - result.q[k + 1]))))
    return deviation


def _min_clearance(task: ObstacleTask, configurations: np.ndarray) -> float:
    desc = robot_description(task.robot)
    data = desc.model.createData()
    clearance = np.inf
    if task.obstacle_constraint == "distance":
        solids = task.solids  # cylinders too, as finite solids
    else:
        solids = tuple(o for o in task.obstacles if isinstance(o, Obstacle))
    for q in configurations:
        if task.cylinders:
            clearance = min(clearance, com_clearances(task, link_coms(desc.model, data, q)).min())
        if solids and desc.collision_model is not None:
            clearance = min(clearance, geometry_distances(desc, q, solids).min())
    return float(clearance)


def _check_shapes(task: ObstacleTask, result: PlanResult) -> None:
    nq = robot_description(task.robot).model.nq
    expected = {"q": (task.N + 1, nq), "v": (task.N + 1, nq), "tau": (task.N, nq)}
    for name, shape in expected.items():
        if getattr(result, name).shape != shape:
            raise InputError(
                f"result.{name}: shape {getattr(result, name).shape} does not match the task "
                f"(expected {shape})"
            )
    if not np.isclose(result.dt, task.dt, rtol=1e-12, atol=0.0):
        raise InputError(f"result.dt = {result.dt} differs from task.dt = {task.dt}")
    if not np.allclose(result.q[0], task.q0, rtol=0.0, atol=1e-9) or np.any(result.v[0] != 0.0):
        raise InputError("result: knot 0 is not the task's initial state (q0, v0 = 0)")


def verify(task: ObstacleTask, result: PlanResult) -> Verification:
    """Check ``result`` against ``task`` with Pinocchio's continuous-time dynamics.

    Raises :class:`InputError` if the result does not belong to the task (shapes, ``dt``, knot 0).
    A result with NaN or inf fails with that reason and NaN metrics.
    """
    _check_shapes(task, result)
    applied = result.tau if result.tau_knots is None else result.tau_knots  # torque extremes
    if not all(np.all(np.isfinite(a)) for a in (result.q, result.v, result.tau, applied)):
        nan = float("nan")
        return Verification(nan, nan, nan, nan, False, ["the trajectory contains NaN or inf"])
    path, q_end, v_end = _interval_replays(task, result)
    q_euler, v_euler = _euler_steps(task, result)
    dev_q = np.max(np.abs(q_end - result.q[1:]), axis=1)
    dev_v = np.max(np.abs(v_end - result.v[1:]), axis=1)
    ratio_q = float(
        np.max(dev_q / (2.0 * np.max(np.abs(q_end - q_euler), axis=1) + DEVIATION_FLOOR))
    )
    ratio_v = float(
        np.max(dev_v / (2.0 * np.max(np.abs(v_end - v_euler), axis=1) + DEVIATION_FLOOR))
    )
    clearance = _min_clearance(task, path.reshape(-1, path.shape[-1]))
    goal = float(np.max(np.abs(q_end[-1] - task.q_target)))
    excess = np.max(np.abs(applied), axis=0) - task.torque_limit  # per joint, N m
    violation = max(float(excess.max()), 0.0)
    reasons = []
    for name, ratio in (("joint", ratio_q), ("velocity", ratio_v)):
        if ratio > 1.0:
            reasons.append(
                f"{name} deviation from the replay is {ratio:.3g} times its threshold "
                "(twice the explicit-Euler error at that knot)"
            )
    if clearance < 0.0:
        reasons.append(f"the replayed motion enters an obstacle ({clearance:.3g} m)")
    if goal > task.goal_tolerance:
        reasons.append(
            f"final goal error {goal:.3g} rad exceeds the tolerance {task.goal_tolerance:g} rad"
        )
    if np.any(excess > TORQUE_TOLERANCE * np.maximum(1.0, task.torque_limit)):
        reasons.append(f"torques exceed the limits by up to {violation:.3g} N m")
    return Verification(
        max_joint_deviation_rad=float(dev_q.max()),
        min_obstacle_distance_m=clearance,
        final_goal_error_rad=goal,
        torque_limit_violation=violation,
        passed=not reasons,
        reasons=reasons,
        max_velocity_deviation=float(dev_v.max()),
        joint_deviation_ratio=ratio_q,
        velocity_deviation_ratio=ratio_v,
        open_loop_deviation_rad=_open_loop_deviation(task, result),
    )
