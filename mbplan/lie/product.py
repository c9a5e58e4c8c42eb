"""Direct products of groups, e.g. SO(3) × R³; elements are tuples of component elements."""

from __future__ import annotations

from collections.abc import Sequence

import casadi as cs
import numpy as np
import scipy.linalg

from mbplan.errors import InputError
from mbplan.lie.backend import Array, is_symbolic


class ProductGroup:
    """``G₁ × … × G_k`` with tangent vectors stacked in component order."""

    def __init__(self, groups: Sequence) -> None:
        if not groups:
            raise InputError("a product group needs at least one factor")
        self.groups = tuple(groups)
        self.dim = sum(g.dim for g in self.groups)
        self.name = " × ".join(g.name for g in self.groups)
        self._splits = np.cumsum([0] + [g.dim for g in self.groups])

    def __repr__(self) -> str:
        return self.name

    def split(self, xi: Array) -> list[Array]:
        """Split a stacked tangent vector into its components."""
        if is_symbolic(xi):
            return [xi[a:b] for a, b in zip(self._splits[:-1], self._splits[1:], strict=True)]
        xi = np.asarray(xi, dtype=float)
        if xi.shape[-1] != self.dim:
            raise InputError(
                f"{self.name}: tangent vector must have {self.dim} entries, got {xi.shape}"
            )
        return [xi[..., a:b] for a, b in zip(self._splits[:-1], self._splits[1:], strict=True)]

    def _parts(self, X: Sequence) -> tuple:
        if len(X) != len(self.groups):
            raise InputError(
                f"{self.name}: element needs {len(self.groups)} components, got {len(X)}"
            )
        return tuple(X)

    def _stack(self, parts: list[Array]) -> Array:
        return cs.vertcat(*parts) if is_symbolic(*parts) else np.concatenate(parts, axis=-1)

    def identity(self) -> tuple:
        return tuple(g.identity() for g in self.groups)

    def exp(self, xi: Array) -> tuple:
        return tuple(g.exp(x) for g, x in zip(self.groups, self.split(xi), strict=True))

    def log(self, X: Sequence) -> Array:
        return self._stack([g.log(x) for g, x in zip(self.groups, self._parts(X), strict=True)])

    def compose(self, X: Sequence, Y: Sequence) -> tuple:
        return tuple(
            g.compose(x, y)
            for g, x, y in zip(self.groups, self._parts(X), self._parts(Y), strict=True)
        )

    def inverse(self, X: Sequence) -> tuple:
        return tuple(g.inverse(x) for g, x in zip(self.groups, self._parts(X), strict=True))

    def retract(self, X: Sequence, xi: Array) -> tuple:
        return tuple(
            g.retract(x, d)
            for g, x, d in zip(self.groups, self._parts(X), self.split(xi), strict=True)
        )

    def local(self, X: Sequence, Y: Sequence) -> Array:
        return self._stack(
            [
                g.local(x, y)
                for g, x, y in zip(self.groups, self._parts(X), self._parts(Y), strict=True)
            ]
        )

    def _blockdiag(self, mats: list[Array]) -> Array:
        if is_symbolic(*mats):
            return cs.diagcat(*mats)
        return scipy.linalg.block_diag(*mats)

    def Ad(self, X: Sequence) -> Array:
        return self._blockdiag([g.Ad(x) for g, x in zip(self.groups, self._parts(X), strict=True)])

    def ad(self, xi: Array) -> Array:
        return self._blockdiag([g.ad(x) for g, x in zip(self.groups, self.split(xi), strict=True)])

    def jac_right(self, xi: Array) -> Array:
        return self._blockdiag(
            [g.jac_right(x) for g, x in zip(self.groups, self.split(xi), strict=True)]
        )

    def jac_left(self, xi: Array) -> Array:
        return self._blockdiag(
            [g.jac_left(x) for g, x in zip(self.groups, self.split(xi), strict=True)]
        )

    def random(self, rng: np.random.Generator, scale: float = 1.0) -> tuple:
        return tuple(g.random(rng, scale) for g in self.groups)
