"""A free rigid body as the robot of an :class:`~mbplan.OCP` (the drone of RIPM §VIII.B).

:class:`FreeBody` holds mass, body inertia ``I_b``, gravity and an actuation map ``B`` (6×nu)
from the input ``u`` to the body wrench ``(f_b, τ_b) = B u`` (the quadrotor, eq. 60: thrust
along body z and body torques, :meth:`FreeBody.quadrotor`). Its state in a plan follows
Pinocchio's free-flyer joint: ``q = (p, quaternion x y z w)`` (nq = 7) and the local velocity
``v = (Rᵀ v_p, ω)`` (nv = 6), where — in the LGVI's convention, eq. (30) — ``v_p`` is the mean
linear velocity over ``[t_k, t_{k+1}]`` and ``F_k = R_kᵀ R_{k+1} = exp(Δt ω_k)`` the rotation step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from mbplan.dynamics.rigid_body import QUADROTOR_ACTUATION
from mbplan.errors import InputError
from mbplan.lie import SO3
from mbplan.validation import as_array, as_real


@dataclass(frozen=True, eq=False)
class FreeBody:
    """A free rigid body: ``mass`` (kg), ``inertia`` (3×3 about the COM, body frame),
    ``gravity`` (m/s², world) and ``actuation`` ``B`` (6×nu, body wrench ``(f, τ) = B u``)."""

    name: str = "free-body"
    mass: float = 1.0
    inertia: np.ndarray = field(default_factory=lambda: np.eye(3))
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    actuation: np.ndarray = field(default_factory=lambda: np.eye(6))

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"FreeBody.name: expected a non-empty string, got {self.name!r}")
        object.__setattr__(self, "mass", as_real(self.mass, "FreeBody.mass", positive=True))
        inertia = as_array(self.inertia, (3, 3), "FreeBody.inertia")
        moments = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
        if not np.allclose(inertia, inertia.T, atol=1e-12 * np.abs(inertia).max()):
            raise InputError("FreeBody.inertia: not symmetric")
        if moments[0] <= 0.0 or moments[0] + moments[1] < moments[2] * (1.0 - 1e-12):
            raise InputError(
                f"FreeBody.inertia: principal moments {moments} are not those of a rigid body "
                "(positive, triangle inequality)"
            )
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "gravity", as_array(self.gravity, (3,), "FreeBody.gravity"))
        B = np.asarray(self.actuation, dtype=float)
        if B.ndim != 2 or B.shape[0] != 6 or B.shape[1] < 1:
            raise InputError(f"FreeBody.actuation: expected shape (6, nu), got {B.shape}")
        object.__setattr__(self, "actuation", as_array(B, B.shape, "FreeBody.actuation"))

    @classmethod
    def quadrotor(
        cls, mass: float, inertia: ArrayLike, gravity: ArrayLike = (0.0, 0.0, -9.81)
    ) -> FreeBody:
        """Thrust ``u_z`` along body z and body torques ``τ``: ``u = (u_z, τ)`` (eq. 60)."""
        B = QUADROTOR_ACTUATION
        return cls("quadrotor", mass, np.asarray(inertia), np.asarray(gravity), B.copy())

    @property
    def nq(self) -> int:
        return 7

    @property
    def nv(self) -> int:
        return 6

    @property
    def nu(self) -> int:
        return self.actuation.shape[1]

    @property
    def nonstandard_inertia(self) -> np.ndarray:
        """``J = tr(I_b)/2 · I₃ - I_b`` (eq. 33)."""
        return 0.5 * np.trace(self.inertia) * np.eye(3) - self.inertia

    @property
    def hover_input(self) -> np.ndarray:
        """The least-squares ``u`` whose wrench cancels gravity with the body upright."""
        wrench = np.r_[-self.mass * self.gravity, np.zeros(3)]
        return np.linalg.lstsq(self.actuation, wrench, rcond=None)[0]

    @property
    def source(self) -> dict[str, Any]:
        return {
            "kind": "free_body",
            "name": self.name,
            "mass": self.mass,
            "inertia": self.inertia.tolist(),
            "gravity": self.gravity.tolist(),
            "actuation": self.actuation.tolist(),
        }

    @classmethod
    def from_source(cls, source: Mapping[str, Any]) -> FreeBody:
        keys = ("name", "mass", "inertia", "gravity", "actuation")
        return cls(**{k: source[k] for k in keys})


def quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)``, ``w ≥ 0`` (Pinocchio's order) of a stack ``R``."""
    return Rotation.from_matrix(R).as_quat(canonical=True)


def rotations(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices of a stack of quaternions ``(x, y, z, w)`` (normalised first)."""
    return Rotation.from_quat(quat).as_matrix()


def body_state(q: np.ndarray, v: np.ndarray, dt: float) -> dict[str, np.ndarray]:
    """``R, p, F, v_p`` of ``q (K, 7)``, ``v (K, 6)`` (module docstring)."""
    q, v = np.atleast_2d(q), np.atleast_2d(v)
    R = rotations(q[:, 3:])
    return {
        "R": R,
        "p": q[:, :3],
        "F": SO3.exp(dt * v[:, 3:]),
        "v": np.einsum("kij,kj->ki", R, v[:, :3]),
    }


def free_flyer_state(
    R: np.ndarray, p: np.ndarray, F: np.ndarray, vp: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`body_state`: ``q (K, 7)``, ``v (K, 6)``."""
    q = np.hstack([p, quaternions(R)])
    v = np.hstack([np.einsum("kji,kj->ki", R, vp), SO3.log(F).reshape(-1, 3) / dt])
    return q, v


def path_state(q_path: np.ndarray, q0: np.ndarray, v0: np.ndarray, dt: float) -> dict:
    """The LGVI state along a pose path ``q_path (N+1, 7)``: ``F_k = R_kᵀ R_{k+1}``,
    ``v_k = (p_{k+1} - p_k)/Δt`` for ``k < N``, at rest at ``N``; knot 0 keeps ``(q0, v0)``."""
    R, p = rotations(q_path[:, 3:]), np.array(q_path[:, :3])
    F = np.repeat(np.eye(3)[None], len(R), axis=0)
    F[:-1] = np.swapaxes(R[:-1], 1, 2) @ R[1:]
    vp = np.zeros_like(p)
    vp[:-1] = np.diff(p, axis=0) / dt
    start = body_state(q0, v0, dt)
    R[0], p[0], F[0], vp[0] = start["R"][0], start["p"][0], start["F"][0], start["v"][0]
    return {"R": R, "p": p, "F": F, "v": vp}
