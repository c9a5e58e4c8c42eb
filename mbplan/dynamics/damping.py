"""Viscous joint damping in the LGVI: the generalized force ``-c q̇`` at knot ``k+1`` (eq. 60).

The forced LGVI row of step ``k`` balances the discrete momentum change against the forces at
knot ``k+1``, so the damping force is evaluated there with the central difference

    q̇_{k+1} = (q(x_{k+2}) - q(x_k)) / (2Δt),

``x_k = (R_{k+1}F_kᵀ, p_{k+1} - v_kΔt)`` and ``x_{k+2} = (R_{k+1}F_{k+1}, p_{k+1} + v_{k+1}Δt)``
(the joint increment of :mod:`mbplan.dynamics.joints`, wrap-free for revolute joints). It is
second order, like the variational integrator itself (a one-sided difference would lag by Δt/2
and make the damped LGVI first order), and implicit in ``F_{k+1}, v_{k+1}``, which the step's
Newton solve or the NLP carries anyway. The force acts along ``∇q(x_{k+1})``, like actuation.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as cs

from mbplan.dynamics.joints import Pose, joint_coordinate_forces


def damping_forces(
    increment: Callable[[Pose, Pose], cs.SX],
    Rp: cs.SX,
    pp: cs.SX,
    Fp0: cs.SX,
    Fp1: cs.SX,
    vp0: cs.SX,
    vp1: cs.SX,
    Rc: cs.SX,
    pc: cs.SX,
    Fc0: cs.SX,
    Fc1: cs.SX,
    vc0: cs.SX,
    vc1: cs.SX,
    damping: cs.SX,
    dt: cs.SX,
) -> cs.SX:
    """Rows (12, as :func:`~mbplan.dynamics.joints.revolute_forces`) of the damping force
    ``-c q̇_{k+1}`` of one joint with coefficient ``c = damping`` (module docstring)."""
    before = (cs.mtimes(Rp, Fp0.T), pp - vp0 * dt, cs.mtimes(Rc, Fc0.T), pc - vc0 * dt)
    after = (cs.mtimes(Rp, Fp1), pp + vp1 * dt, cs.mtimes(Rc, Fc1), pc + vc1 * dt)
    rate = increment(before, after) / (2.0 * dt)
    return joint_coordinate_forces(increment, (Rp, pp, Rc, pc), -damping * rate)
