"""Batched configuration-space arithmetic of a Pinocchio model: ``q ⊕ δ`` and ``b ⊖ a``.

Plain vector arithmetic when ``nq = nv`` (1-dof joints, continuous ones as unbounded angles);
Pinocchio's ``integrate`` and ``difference`` otherwise (a floating base: its position and unit
quaternion, with the base's local velocity as tangent)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def integrate(model: pin.Model, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """``q ⊕ dq`` for ``q (..., nq)`` and tangents ``dq (..., nv)``."""
    q, dq = np.asarray(q, dtype=float), np.asarray(dq, dtype=float)
    if model.nq == model.nv:
        return q + dq
    shape = np.broadcast_shapes(q.shape[:-1], dq.shape[:-1])
    qs = np.broadcast_to(q, (*shape, model.nq)).reshape(-1, model.nq)
    ds = np.broadcast_to(dq, (*shape, model.nv)).reshape(-1, model.nv)
    out = [pin.integrate(model, a, d) for a, d in zip(qs, ds, strict=True)]
    return np.array(out).reshape(*shape, model.nq)


def difference(model: pin.Model, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``b ⊖ a`` (the tangent ``δ`` with ``a ⊕ δ = b``) for ``a, b (..., nq)``: ``(..., nv)``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if model.nq == model.nv:
        return b - a
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    As = np.broadcast_to(a, (*shape, model.nq)).reshape(-1, model.nq)
    Bs = np.broadcast_to(b, (*shape, model.nq)).reshape(-1, model.nq)
    out = [pin.difference(model, x, y) for x, y in zip(As, Bs, strict=True)]
    return np.array(out).reshape(*shape, model.nv)
