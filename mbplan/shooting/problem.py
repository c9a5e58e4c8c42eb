"""A shooting optimal-control problem on a Lie-group state space (thesis §3, problem 3-1).

``min Σ_{k<N} l_k(x_k, u_k) + l_N(x_N)`` s.t. ``x_{k+1} = F(x_k, u_k)``, ``x_0`` given, with the
tracking costs of :class:`~mbplan.shooting.cost.TrackingCost`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError
from mbplan.shooting.cost import TrackingCost
from mbplan.shooting.dynamics import DiscreteDynamics
from mbplan.shooting.space import StateSpace


def _vector(a, n: int, what: str) -> np.ndarray:
    try:
        v = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what}: not a float array") from exc
    if v.shape != (n,):
        raise InputError(f"{what}: expected shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError(f"{what}: weights must be finite and non-negative")
    return v


class ShootingBase:
    """What SS-/MS-iLQR use of a problem (3-1): the dynamics ``x_{k+1} = F(x_k, u_k)`` from
    ``x0``, states ``x_ref (N+1, nq)`` (MS-iLQR's default initial states), and the cost's value
    and derivatives along a trajectory (flat states, see StateSpace)."""

    dynamics: DiscreteDynamics
    x0: np.ndarray
    x_ref: np.ndarray

    @property
    def N(self) -> int:
        return self.x_ref.shape[0] - 1

    @property
    def space(self) -> StateSpace:
        return self.dynamics.space

    @property
    def nu(self) -> int:
        return self.dynamics.nu

    def cost_value(self, X: np.ndarray, U: np.ndarray) -> float:
        """``Σ_{k<N} l_k(x_k, u_k) + l_N(x_N)``."""
        raise NotImplementedError

    def cost_derivatives(
        self, X: np.ndarray, U: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Total cost and ``l_x (N+1, nx)``, ``l_xx (N+1, nx, nx)``, ``l_u``, ``l_uu`` (N rows);
        ``l_ux = 0``."""
        raise NotImplementedError


@dataclass
class ShootingProblem(ShootingBase):
    """Dynamics, tracking cost, initial state and references (flat states, see StateSpace)."""

    dynamics: DiscreteDynamics
    cost: TrackingCost
    x0: np.ndarray
    x_ref: np.ndarray
    """``(N+1, nq)`` state reference (knot 0 included)."""
    u_ref: np.ndarray
    """``(N, nu)`` input reference."""
    state_weights: np.ndarray
    input_weights: np.ndarray
    terminal_weights: np.ndarray

    def __post_init__(self) -> None:
        space = self.dynamics.space
        nu = self.dynamics.nu
        if self.cost.space is not space and self.cost.space.name != space.name:
            raise InputError("cost and dynamics live on different state spaces")
        self.x0 = space.check(self.x0, "initial state x0")
        if self.x0.shape != (space.nq,):
            raise InputError(f"initial state x0: expected shape ({space.nq},), got {self.x0.shape}")
        self.x_ref = space.check(self.x_ref, "state reference")
        if self.x_ref.ndim != 2 or self.x_ref.shape[0] < 2:
            raise InputError(f"state reference: expected (N+1, {space.nq}) with N >= 1")
        N = self.x_ref.shape[0] - 1
        u_ref = np.asarray(self.u_ref, dtype=float)
        if u_ref.shape != (N, nu):
            raise InputError(f"input reference: expected shape ({N}, {nu}), got {u_ref.shape}")
        if not np.all(np.isfinite(u_ref)):
            raise InputError("input reference: contains NaN or inf")
        self.u_ref = u_ref
        self.state_weights = _vector(self.state_weights, space.nx, "state weights")
        self.input_weights = _vector(self.input_weights, nu, "input weights")
        self.terminal_weights = _vector(self.terminal_weights, space.nx, "terminal weights")
        # Stage and terminal knots in one vectorised call: row N has the terminal weights and
        # no input term.
        self._wq = np.vstack([np.tile(self.state_weights, (N, 1)), self.terminal_weights])
        self._wu = np.vstack([np.tile(self.input_weights, (N, 1)), np.zeros(nu)])
        self._uref = np.vstack([u_ref, np.zeros(nu)])

    def _padded(self, U: np.ndarray) -> np.ndarray:
        return np.vstack([U, np.zeros((1, self.nu))])

    def cost_value(self, X: np.ndarray, U: np.ndarray) -> float:
        values = self.cost.values(X, self._padded(U), self.x_ref, self._uref, self._wq, self._wu)
        return float(np.sum(values))

    def cost_derivatives(self, X: np.ndarray, U: np.ndarray):
        l, lx, lxx, lu, luu = self.cost.derivatives(
            X, self._padded(U), self.x_ref, self._uref, self._wq, self._wu
        )
        return float(np.sum(l)), lx, lxx, lu[:-1], luu[:-1]
