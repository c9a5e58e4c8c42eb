"""State spaces of shooting problems: products of :mod:`mbplan.lie` groups, stored flat.

A state is a tuple of group elements, one per factor (SO(3), SE(3), SO(n), Rⁿ, …). Numerically a
trajectory is one ``(K, nq)`` array: matrix factors flattened column-major (CasADi's ``vec``),
vector factors as they are. Perturbations are ``x ⊕ δx = (X₁ exp(δ₁), …)`` with tangent vectors
stacked in factor order (thesis §3-1, the right-plus); ``x ⊖ y = log(y⁻¹x)`` is its inverse.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.lie import RnGroup


class StateSpace:
    """``G₁ × … × G_m`` with flat storage of ``nq`` numbers and tangent dimension ``nx``."""

    def __init__(self, groups: Sequence) -> None:
        if not groups:
            raise InputError("a state space needs at least one factor")
        self.groups = tuple(groups)
        self.name = " × ".join(g.name for g in self.groups)
        self._sizes = [int(np.prod(g.element_shape)) for g in self.groups]
        self._q = np.cumsum([0, *self._sizes])
        self._t = np.cumsum([0, *(g.dim for g in self.groups)])
        self.nq = int(self._q[-1])
        self.nx = int(self._t[-1])

    def __repr__(self) -> str:
        return f"StateSpace({self.name})"

    def tangent_slice(self, i: int) -> slice:
        return slice(int(self._t[i]), int(self._t[i + 1]))

    # ------------------------------------------------------------------ numeric packing
    def pack(self, parts: Sequence) -> np.ndarray:
        """Group elements (each with the same leading batch shape) → flat ``(..., nq)`` array."""
        if len(parts) != len(self.groups):
            raise InputError(f"{self.name}: state needs {len(self.groups)} components")
        flat = []
        for g, x in zip(self.groups, parts, strict=True):
            a = g.check(x)
            flat.append(
                a if isinstance(g, RnGroup) else np.swapaxes(a, -1, -2).reshape(*a.shape[:-2], -1)
            )
        return np.concatenate(flat, axis=-1)

    def unpack(self, q: np.ndarray) -> list[np.ndarray]:
        """Flat ``(..., nq)`` → list of group elements (matrices or vectors)."""
        q = np.asarray(q, dtype=float)
        out = []
        for i, g in enumerate(self.groups):
            piece = q[..., self._q[i] : self._q[i + 1]]
            if isinstance(g, RnGroup):
                out.append(piece)
            else:
                n = g.n
                out.append(np.swapaxes(piece.reshape(*piece.shape[:-1], n, n), -1, -2))
        return out

    def check(self, q: np.ndarray, what: str = "state") -> np.ndarray:
        """Validate a flat state (or trajectory): shape, finiteness, group membership."""
        try:
            a = np.asarray(q, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{what}: not a float array") from exc
        if a.ndim == 0 or a.shape[-1] != self.nq:
            raise InputError(
                f"{what}: expected shape (..., {self.nq}) for {self.name}, got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise InputError(f"{what}: contains NaN or inf")
        for g, x in zip(self.groups, self.unpack(a), strict=True):
            try:
                g.check(x)
            except InputError as exc:
                raise InputError(f"{what}: {exc}") from None
        return a

    def violation(self, q: np.ndarray) -> float:
        """Largest distance of any matrix factor from its group (``‖XᵀX - I‖∞`` on rotations,
        and the last row of SE(3))."""
        worst = 0.0
        for g, x in zip(self.groups, self.unpack(q), strict=True):
            if isinstance(g, RnGroup):
                continue
            if g.name == "SE(3)":
                R = x[..., :3, :3]
                bottom = np.abs(x[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0]))
                worst = max(worst, float(np.max(bottom, initial=0.0)))
            else:
                R = x
            err = np.swapaxes(R, -1, -2) @ R - np.eye(R.shape[-1])
            worst = max(worst, float(np.max(np.abs(err), initial=0.0)))
        return worst

    # ------------------------------------------------------------------ symbolic maths
    def sym_unpack(self, q: cs.SX) -> list[cs.SX]:
        out = []
        for i, g in enumerate(self.groups):
            piece = q[int(self._q[i]) : int(self._q[i + 1])]
            out.append(piece if isinstance(g, RnGroup) else cs.reshape(piece, g.n, g.n))
        return out

    def sym_pack(self, parts: Sequence[cs.SX]) -> cs.SX:
        return cs.vertcat(*[cs.vec(p) for p in parts])

    def sym_split(self, dx: cs.SX) -> list[cs.SX]:
        return [dx[int(self._t[i]) : int(self._t[i + 1])] for i in range(len(self.groups))]

    def sym_retract(self, q: cs.SX, dx: cs.SX, *, second_order: bool = False) -> cs.SX:
        """``x ⊕ δx``; ``second_order`` uses ``X(I + δ^ + δ^²/2)`` (same derivatives at 0)."""
        parts = []
        for g, X, d in zip(self.groups, self.sym_unpack(q), self.sym_split(dx), strict=True):
            if second_order:
                parts.append(g.retract_second_order(X, d))
            else:
                parts.append(g.compose(X, g.exp(d)))
        return self.sym_pack(parts)

    def sym_local(self, q: cs.SX, y: cs.SX) -> cs.SX:
        """``y ⊖ x = log(x⁻¹ y)`` per factor (exact, branch-safe logarithms)."""
        return cs.vertcat(
            *[
                g.log(g.compose(g.inverse(X), Y))
                for g, X, Y in zip(self.groups, self.sym_unpack(q), self.sym_unpack(y), strict=True)
            ]
        )

    def sym_local_linear(self, q: cs.SX, y: cs.SX) -> cs.SX:
        """``vee(x⁻¹ y - I)`` per factor: equals ``y ⊖ x`` to first order around ``y = x``."""
        out = []
        for g, X, Y in zip(self.groups, self.sym_unpack(q), self.sym_unpack(y), strict=True):
            if isinstance(g, RnGroup):
                out.append(Y - X)
            else:
                out.append(g.vee(g.compose(g.inverse(X), Y) - cs.DM.eye(g.n)))
        return cs.vertcat(*out)
