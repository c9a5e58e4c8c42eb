"""Crocoddyl FDDP on the thesis scenarios that a Crocoddyl model expresses.

A (SO(3) tracking) is a rigid body on a spherical joint, B2 (SE(3)) a free-flyer, both fully
actuated, with Pinocchio's forward dynamics (the same continuous Euler–Poincaré equations) and
Crocoddyl's Euler integrator — *semi-implicit* (``q⁺ = q ⊕ h v⁺``), not the thesis' explicit
forward Euler, so FDDP solves a slightly different discrete problem. Costs: ``FrameRotation`` /
``FramePlacement`` residuals (the right error ``log(X_ref⁻¹X)``; on SO(3) its norm equals the
left error's, on SE(3) the translation part differs), velocity tracking, input, the same weights
(doubled: Crocoddyl's quadratic activation carries ½). The pendulum (pivot-acceleration input)
and the drone (input ``(f_z, τ)``) need custom actuation models and are not run.
"""

from __future__ import annotations

import time

import crocoddyl
import numpy as np
import pinocchio as pin

from mbplan.benchmarks.ilqr.baselines import BaselineRun, rotation_to_quaternion
from mbplan.lie import SO3
from mbplan.tasks.ilqr import Scenario

FDDP_SCENARIOS = ("so3-tracking", "se3-tracking")


def _model(se3: bool, inertia: np.ndarray) -> tuple[pin.Model, int]:
    model = pin.Model()
    joint = pin.JointModelFreeFlyer() if se3 else pin.JointModelSpherical()
    jid = model.addJoint(0, joint, pin.SE3.Identity(), "body_joint")
    J = inertia[3:, 3:] if se3 else inertia
    model.appendBodyToJoint(jid, pin.Inertia(1.0, np.zeros(3), J), pin.SE3.Identity())
    fid = model.addFrame(pin.Frame("body", jid, pin.SE3.Identity(), pin.FrameType.BODY))
    model.gravity = pin.Motion.Zero()
    return model, fid


def _pin_states(sc: Scenario) -> np.ndarray:
    """The scenario's reference as Crocoddyl states ``[q (xyzw quaternion, position), v]``."""
    pb = sc.problem
    X, xi = pb.space.unpack(pb.x_ref)
    se3 = sc.group.name == "SE(3)"
    R = X[:, :3, :3] if se3 else X
    q = rotation_to_quaternion(R)[:, [1, 2, 3, 0]]
    parts = [X[:, :3, 3], q] if se3 else [q]
    return np.hstack([*parts, xi])


def fddp_baseline(sc: Scenario) -> BaselineRun:
    """Solve ``sc`` (A or B2) with Crocoddyl's FDDP from the reference states and zero inputs."""
    if sc.name not in FDDP_SCENARIOS:
        raise ValueError(f"fddp: scenario {sc.name!r} has no Crocoddyl model")
    pb = sc.problem
    se3 = sc.group.name == "SE(3)"
    model, fid = _model(se3, sc.inertia)
    state = crocoddyl.StateMultibody(model)
    actuation = crocoddyl.ActuationModelFull(state)
    nu, N, d = actuation.nu, pb.N, sc.group.dim
    X, _ = pb.space.unpack(pb.x_ref)
    xs_ref = _pin_states(sc)
    wq, wu = pb.state_weights, pb.input_weights

    def node(k: int, terminal: bool):
        scale = 1.5 if terminal else 1.0
        costs = crocoddyl.CostModelSum(state, nu)
        if se3:
            placement = pin.SE3(X[k, :3, :3], X[k, :3, 3])
            pose = crocoddyl.ResidualModelFramePlacement(state, fid, placement, nu)
            w_pose = 2 * scale * wq[:d]
        else:
            pose = crocoddyl.ResidualModelFrameRotation(state, fid, X[k], nu)
            w_pose = 2 * scale * wq[:d]
        costs.addCost(
            "pose",
            crocoddyl.CostModelResidual(state, crocoddyl.ActivationModelWeightedQuad(w_pose), pose),
            1.0,
        )
        w_vel = np.concatenate([np.zeros(state.ndx - d), 2 * scale * wq[d:]])
        velocity = crocoddyl.ResidualModelState(state, xs_ref[k], nu)
        costs.addCost(
            "velocity",
            crocoddyl.CostModelResidual(
                state, crocoddyl.ActivationModelWeightedQuad(w_vel), velocity
            ),
            1.0,
        )
        if not terminal:
            control = crocoddyl.ResidualModelControl(state, nu)
            costs.addCost(
                "input",
                crocoddyl.CostModelResidual(
                    state, crocoddyl.ActivationModelWeightedQuad(2 * wu), control
                ),
                1.0,
            )
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs)
        return crocoddyl.IntegratedActionModelEuler(dam, 0.0 if terminal else sc.dt)

    x0 = _pin_states_single(sc, pb.x0)
    problem = crocoddyl.ShootingProblem(x0, [node(k, False) for k in range(N)], node(N, True))
    problem.nthreads = 1  # as every other method here (and no OpenMP spinning on a shared machine)
    solver = crocoddyl.SolverFDDP(problem)
    # FDDP stops on Σ_k ‖Q_u,k‖²; N·tol² matches a mean gradient norm of about tol.
    solver.th_stop = N * 1e-16
    history: list[tuple[float, float, float]] = []

    class _Log(crocoddyl.CallbackAbstract):
        def __init__(self) -> None:
            crocoddyl.CallbackAbstract.__init__(self)

        def __call__(self, s) -> None:
            history.append((float(s.cost), float(np.sqrt(max(s.stop, 0.0) / N)), float(s.ffeas)))

    solver.setCallbacks([_Log()])
    xs = [x0] + [xs_ref[k] for k in range(1, N + 1)]
    us = [np.zeros(nu)] * N
    t = time.perf_counter()
    converged = solver.solve(xs, us, sc.max_iter, False)
    wall = time.perf_counter() - t
    xs_sol = np.asarray(solver.xs)
    quat = xs_sol[:, 3:7] if se3 else xs_sol[:, :4]
    viol = float(np.max(np.abs(np.linalg.norm(quat, axis=1) - 1)))
    R = np.stack([pin.Quaternion(q[3], q[0], q[1], q[2]).normalized().matrix() for q in quat])
    R = SO3.exp(SO3.log(R))  # exact rotations for the cost evaluation
    xi = xs_sol[:, -d:]
    if se3:
        Xs = np.tile(np.eye(4), (N + 1, 1, 1))
        Xs[:, :3, :3] = R
        Xs[:, :3, 3] = xs_sol[:, :3]
    else:
        Xs = R
    return BaselineRun(
        method="fddp",
        converged=bool(converged),
        status="converged" if converged else "not converged",
        iterations=int(solver.iter),
        time_s=wall,
        x=pb.space.pack([Xs, xi]),
        u=np.asarray(solver.us),
        max_defect=float(solver.ffeas),
        group_violation=viol,
        history={
            "objective": [h[0] for h in history],
            "inf_du": [h[1] for h in history],
            "inf_pr": [h[2] for h in history],
        },
    )


def _pin_states_single(sc: Scenario, x: np.ndarray) -> np.ndarray:
    X, xi = sc.problem.space.unpack(x)
    se3 = sc.group.name == "SE(3)"
    R = X[:3, :3] if se3 else X
    q = rotation_to_quaternion(R[None])[0][[1, 2, 3, 0]]
    return np.concatenate([X[:3, 3], q, xi] if se3 else [q, xi])
