"""Independent check of a planned trajectory against Pinocchio's continuous-time dynamics.

:func:`verify` integrates the robot's equations of motion (``pinocchio.aba`` with the model's
viscous joint damping ``-D v``, RK4 with :data:`SUBSTEPS` steps per interval,
:func:`mbplan.simulation.reference.integrate_aba`) under the planned torques, and measures how far
the plan is from that motion, from the obstacles, from the
goal and from the torque limits. It shares no code with the planners' transcriptions.

Torques are replayed as each transcription applies them. Eq. (61) holds ``τ_k`` over
``[t_k, t_{k+1}]`` (zero-order hold). The LGVI applies forces at the knots with trapezoidal
weights (eq. 29): its step ``q_{k+1} = q_k + Δt v_k + ½Δt² q̈_k`` sees ``τ_k`` only, and
``v_{k+1} - v_k = ½Δt (q̈_k + q̈_{k+1})``. Its plans carry ``tau_knots``, replayed by linear
interpolation (first-order hold), which leaves the LGVI's own local error ``⅙Δt²|q̈_k - q̈_{k+1}|``
in ``q``; the interval mean held instead adds ``¼Δt²|q̈_k - q̈_{k+1}|``, a first-order error where
the torque turns quickly (the launch at knot 1, leaving a velocity limit): with it, 17 of 97
converged RIPM plans of the iiwa benchmark failed the deviation ratios (up to 1.86), with linear
interpolation 1 does (1.002), and the median ratio drops from 0.74 to 0.56. A plan with contacts
(:mod:`mbplan.verification.contacts`) is replayed as the LGVI applies its knot forces, as impulses
``½Δt (τ_k + Σ J_iᵀ f_{i,k})`` at both ends of each interval (velocity Verlet: its positions do
not see the next knot's forces) with the unforced dynamics between: its contact forces switch on
and off within one knot (a touchdown impulse, a push-off) on light legs, where a ramp's
``⅙Δt²|q̈_k - q̈_{k+1}|`` reaches the velocity threshold; such a plan's ``v_k`` is the velocity
midway through the knot's impulse
(:func:`~mbplan.formulations.maximal.impulse_midpoint_velocities`).

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
  step ``(q_k + Δt v_k, v_k + Δt·aba(q_k, v_k, τ_k))`` is an exactly known solution of eq. (61)
  (with viscous joint damping ``D``, taken at ``v_{k+1}`` as eq. 61 does, so the reference stays
  accurate where the damping is stiff, ``λ(M⁻¹D) Δt ≫ 1``; explicit damping there would make
  ``e_k`` grow with ``D`` and pass plans that ignore it), and its distance ``e_k`` to the replay is
  the discretisation error of a first-order scheme
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
* every constraint of the OCP, by name (:attr:`Verification.violations`): obstacle constraints
  (:attr:`~mbplan.residuals.Residual.is_obstacle`: :class:`~mbplan.residuals.Distance`,
  :class:`~mbplan.residuals.ComOutsideCylinder`) on every RK4 substep of the replayed intervals
  (:data:`SUBSTEPS` or more per interval), by name (``clearances``), coal through the planner's
  own path (:mod:`mbplan.multibody.collision`): without their margin ``min_obstacle_distance_m``
  ≥ 0, and a constraint with ``between_knots`` must keep
  :data:`~mbplan.verification.report.MARGIN_KEPT` of its margin (``margin_kept``); the others at
  the planned knots within
  :data:`~mbplan.residuals.base.CONSTRAINT_TOLERANCE` (or the constraint's own ``tolerance``;
  :meth:`~mbplan.residuals.Residual.violation_tolerance`); torque limits on the applied torques
  (``tau_knots`` when given) within :data:`~mbplan.residuals.base.TORQUE_TOLERANCE`
  ``· max(1, limit)``.
* a robot with closed loops or passive joints (:mod:`mbplan.verification.loops`): the replay
  and the reference step use the loops' constraint dynamics, the planned knots must close the
  loops (``closure_residual``) and the passive joints' torques vanish (``passive_torque_nm``).
* a replay that diverges (a non-finite state in any interval, e.g. an open-loop unstable
  configuration held over ``Δt``) fails: its NaN metrics would pass every comparison.
* soft goals (costs with a ``tolerance``): the residual's ∞-norm at the end of the replayed
  last interval (``goal_errors``; ``final_goal_error_rad`` is the largest) ≤ the tolerance (the
  tracking cost is soft, so a plan that converged to a local minimum blocked by the obstacle
  fails here).
"""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.formulations.joint_space import evaluate
from mbplan.ocp.problem import OCP, Item
from mbplan.results import PlanResult
from mbplan.robots.configuration import difference, integrate
from mbplan.robots.free_body import FreeBody
from mbplan.simulation.reference import damped_euler_velocity, damping_rate, integrate_aba
from mbplan.verification.contacts import (
    contact_dynamics,
    contact_reasons,
    contact_violations,
    impulse_sag,
    kick,
    replay_slip,
    with_contact_forces,
)
from mbplan.verification.loops import (
    baumgarte_rate,
    closure_error,
    closure_reasons,
    euler_velocity,
    passive_reasons,
    passive_torque,
    rk4_step,
)
from mbplan.verification.report import (
    Verification,
    constraint_violations,
    goal_errors,
    margin_kept,
    replay_reasons,
)

SUBSTEPS = 20  # RK4 steps per interval: at Δt = 0.075 s, 20 and 40 agree to < 1e-8 rad
DAMPING_STEP = 0.5  # RK4 substep h ≤ DAMPING_STEP / λ_max(M⁻¹D) (stiff damping of light links)
DEVIATION_FLOOR = 1e-5  # rad and rad/s: IPOPT's tolerance on the eq. (61) rows, after Δt scaling


def _interval_replays(ocp: OCP, result: PlanResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RK4 replay of every interval from the planned knot: substep configurations
    ``(N, S+1, nq)`` and end states ``q, v (N, nq)`` (``S``: :func:`substeps`)."""
    model = ocp.robot.model
    steps = substeps(ocp, result)
    h = ocp.dt / steps
    path = np.empty((ocp.N, steps + 1, model.nq))
    v_end = np.empty((ocp.N, model.nv))
    for k in range(ocp.N):
        q, v = result.q[k], result.v[k]
        path[k, 0] = q
        for s in range(steps):
            q, v = _replay_step(ocp, q, v, result, k, s * h, h)
            path[k, s + 1] = q
        v_end[k] = v
    return path, path[:, -1], v_end


def substeps(ocp: OCP, result: PlanResult) -> int:
    """RK4 substeps per interval: :data:`SUBSTEPS`, more where viscous joint damping is stiff
    (``Δt/S ≤`` :data:`DAMPING_STEP` ``/ λ_max(M(q_k)⁻¹ D)`` at the planned knots; RK4 is
    unstable beyond ``hλ ≈ 2.8``)."""
    rate = max(damping_rate(ocp.robot.model, q) for q in result.q)
    return max(SUBSTEPS, int(np.ceil(ocp.dt * rate / DAMPING_STEP)))


def _replay_step(
    ocp: OCP, q: np.ndarray, v: np.ndarray, result: PlanResult, k: int, t: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """RK4 over ``[t_k + t, t_k + t + h]`` under the plan's torque: ``τ_k`` held, or the linear
    ramp between ``tau_knots[k]`` and ``tau_knots[k+1]`` when the plan has knot torques; with
    the loops' constraint dynamics (:mod:`mbplan.verification.loops`) if the robot has loops."""
    tau, tau_end = result.tau[k], None
    if result.tau_knots is not None:
        a, b = result.tau_knots[k], result.tau_knots[k + 1]
        s0, s1 = t / result.dt, (t + h) / result.dt
        tau, tau_end = a + s0 * (b - a), a + s1 * (b - a)
    if ocp.robot.loops:
        return rk4_step(ocp.robot, q, v, tau, h, baumgarte_rate(ocp.N, ocp.dt), tau_end)
    if ocp.contacts and result.tau_knots is not None:  # the LGVI's impulses (module docstring)
        knots, forces = result.tau_knots, result.contact_forces_knots
        if t == 0.0:
            v = kick(ocp, q, v, knots[k], forces[k], 0.5 * ocp.dt)
        q, v = integrate_aba(ocp.robot.model, q, v, np.zeros_like(tau), h, 1, damping=True)
        if np.isclose(t + h, ocp.dt, rtol=1e-9, atol=0.0):
            v = kick(ocp, q, v, knots[k + 1], forces[k + 1], 0.5 * ocp.dt)
        return q, v
    if ocp.contacts:  # eq. (61): the interval's contact forces held
        u = np.concatenate([tau, result.contact_forces[k].ravel()])
        u_end = None if tau_end is None else np.concatenate([tau_end, u[len(tau) :]])
        return integrate_aba(
            ocp.robot.model, q, v, u, h, 1, tau_end=u_end, acceleration=contact_dynamics(ocp)
        )
    return integrate_aba(ocp.robot.model, q, v, tau, h, 1, tau_end=tau_end, damping=True)


def _euler_steps(ocp: OCP, result: PlanResult) -> tuple[np.ndarray, np.ndarray]:
    """One explicit-Euler step of eq. (61) from each planned knot (damping implicit,
    :func:`~mbplan.simulation.reference.damped_euler_velocity`): ``q, v (N, nq)``."""
    model = ocp.robot.model
    data = model.createData()
    q, v, tau, dt = result.q[:-1], result.v[:-1], result.tau, ocp.dt
    if ocp.robot.loops:
        v_next = [euler_velocity(ocp.robot, q[k], v[k], tau[k], dt) for k in range(ocp.N)]
        return integrate(model, q, dt * v), np.array(v_next)
    v_next = [
        damped_euler_velocity(
            model, data, q[k], v[k], with_contact_forces(ocp, result, k, tau[k]), dt
        )
        for k in range(ocp.N)
    ]
    return integrate(model, q, dt * v), np.array(v_next)


def _open_loop_deviation(ocp: OCP, result: PlanResult) -> float:
    q, v = ocp.q0, ocp.v0
    deviation = 0.0
    steps = substeps(ocp, result)
    h = ocp.dt / steps
    for k in range(ocp.N):
        for s in range(steps):
            q, v = _replay_step(ocp, q, v, result, k, s * h, h)
        gap = difference(ocp.robot.model, result.q[k + 1], q)
        deviation = max(deviation, float(np.max(np.abs(gap))))
    return deviation


def check_shapes(ocp: OCP, result: PlanResult) -> None:
    robot = ocp.robot
    nu = robot.nu if isinstance(robot, FreeBody) else robot.nv
    expected = {"q": (ocp.N + 1, robot.nq), "v": (ocp.N + 1, robot.nv), "tau": (ocp.N, nu)}
    for name, shape in expected.items():
        if getattr(result, name).shape != shape:
            raise InputError(
                f"result.{name}: shape {getattr(result, name).shape} does not match the OCP "
                f"(expected {shape})"
            )
    if ocp.contacts and result.contact_forces is None:
        raise InputError("result: the OCP has contacts, the plan has no contact forces")
    if not np.isclose(result.dt, ocp.dt, rtol=1e-12, atol=0.0):
        raise InputError(f"result.dt = {result.dt} differs from the OCP's dt = {ocp.dt}")
    if not np.allclose(result.q[0], ocp.q0, rtol=0.0, atol=1e-9) or not np.allclose(
        result.v[0], ocp.v0, rtol=0.0, atol=1e-9
    ):
        raise InputError("result: knot 0 is not the OCP's initial state (q0, v0)")


def _clearance(ocp: OCP, item: Item, q: np.ndarray) -> float:
    """Smallest clearance (m) without the margin of an obstacle constraint along ``q (K, nq)``."""

    def rows(residual, path):
        return evaluate(ocp.robot, ocp.scene, residual, path, path, None)

    return item.residual.clearance(ocp.robot, ocp.scene, q, rows)


def verify_multibody(ocp: OCP, result: PlanResult) -> Verification:
    """Check a multibody plan with finite values against ``ocp`` (module docstring)."""
    path, q_end, v_end = _interval_replays(ocp, result)
    q_euler, v_euler = _euler_steps(ocp, result)
    model = ocp.robot.model
    dev_q = np.max(np.abs(difference(model, result.q[1:], q_end)), axis=1)
    dev_v = np.max(np.abs(v_end - result.v[1:]), axis=1)
    euler_q = np.max(np.abs(difference(model, q_euler, q_end)), axis=1)
    ratio_q = float(np.max(dev_q / (2.0 * euler_q + DEVIATION_FLOOR)))
    ratio_v = float(
        np.max(dev_v / (2.0 * np.max(np.abs(v_end - v_euler), axis=1) + DEVIATION_FLOOR))
    )
    reasons = []
    finite = np.isfinite(path).all(axis=(1, 2)) & np.isfinite(v_end).all(axis=1)
    if not finite.all():
        reasons.append(
            f"the replay diverges (non-finite state) in {int(np.sum(~finite))} of {ocp.N} "
            f"intervals, the first from knot {int(np.argmin(finite))}"
        )
    for name, ratio in (("joint", ratio_q), ("velocity", ratio_v)):
        if ratio > 1.0:
            reasons.append(
                f"{name} deviation from the replay is {ratio:.3g} times its threshold "
                "(twice the explicit-Euler error at that knot)"
            )
    violations = constraint_violations(ocp, result.q, result.v, result.tau, result.tau_knots)
    violations |= contact_violations(ocp, result.q, result.contact_forces)
    impulses = ocp.contacts and result.tau_knots is not None and not ocp.robot.loops
    sag = impulse_sag(ocp, result) if impulses else None
    violations |= replay_slip(ocp, path, q_euler, sag)
    substeps = path.reshape(-1, path.shape[-1])
    clearances = {
        i.name: _clearance(ocp, i, substeps) for i in ocp.constraints if i.residual.is_obstacle
    }
    q_final = np.vstack([result.q[:-1], q_end[-1:]])
    v_final = np.vstack([result.v[:-1], v_end[-1:]])
    goals = goal_errors(ocp, q_final, v_final)
    reasons += replay_reasons(ocp, violations, clearances, goals)
    reasons += contact_reasons(ocp, violations, result.contact_forces)
    closure = closure_error(ocp.robot, result.q)
    passive = passive_torque(ocp.robot, result.tau, result.tau_knots)
    reasons += closure_reasons(ocp.robot, closure) + passive_reasons(ocp.robot, passive, result.tau)
    torque = [i for i in ocp.constraints if i.residual.input_limits]
    violation = max((violations[i.name] for i in torque), default=0.0)
    return Verification(
        max_joint_deviation_rad=float(dev_q.max()),
        min_obstacle_distance_m=float(min(clearances.values(), default=np.inf)),
        final_goal_error_rad=max(goals.values(), default=float("nan")),
        torque_limit_violation=violation,
        passed=not reasons,
        reasons=reasons,
        max_velocity_deviation=float(dev_v.max()),
        joint_deviation_ratio=ratio_q,
        velocity_deviation_ratio=ratio_v,
        open_loop_deviation_rad=_open_loop_deviation(ocp, result),
        violations=violations,
        goal_errors=goals,
        closure_residual=closure,
        passive_torque_nm=passive,
        clearances=clearances,
        margin_kept=margin_kept(ocp, clearances),
    )
