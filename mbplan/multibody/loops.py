"""Loop closures in maximal coordinates: a closure is a constraint between two bodies.

A :class:`~mbplan.robots.loops.Loop` joins a frame on joint ``joint1``'s body to one on joint
``joint2``'s body (or the world). In maximal coordinates each frame is fixed in its body: with the
body pose ``(R, p)`` (orientation of the joint frame, origin at the COM) and the frame placement
``M`` in the joint frame, the frame's world pose is ``(R Rf, p + R r)`` with ``Rf = M.R`` and
``r = M.t - com_in_joint`` (for the world, ``R = I``, ``p = 0``, ``r = M.t``). The closure's
residual is :func:`~mbplan.robots.loops.loop_residual` of the two frames, its imposed rows
(:attr:`~mbplan.robots.loops.Loop.rows`) a holonomic constraint ``h(x) = 0`` of the bodies' poses
like a joint's (RIPM paper eq. 24, 28), whose force ``J(x)ᵀλ`` acts on both bodies (eq. 26–27).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as cs
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from mbplan.robots.loops import Loop, loop_from_spec, loop_residual


@dataclass(frozen=True, eq=False)
class MaximalLoop:
    """A closure between bodies ``body1`` and ``body2`` (``-1``: the world): its frames'
    rotations ``Rf`` and offsets ``r`` from the COM in the body frames, its kind and imposed
    rows (indices into :data:`~mbplan.robots.loops.LOOP_KINDS` ``[kind]``)."""

    name: str
    kind: str
    rows: tuple[int, ...]
    body1: int
    Rf1: np.ndarray  # (3, 3)
    r1: np.ndarray  # (3,)
    body2: int
    Rf2: np.ndarray  # (3, 3)
    r2: np.ndarray  # (3,)

    @property
    def dim(self) -> int:
        """Number of imposed rows (multipliers)."""
        return len(self.rows)

    @property
    def group(self) -> tuple[str, tuple[int, ...], bool, bool]:
        """What its residual function depends on: kind, rows, which sides are the world."""
        return self.kind, self.rows, self.body1 < 0, self.body2 < 0


def maximal_loops(
    model: pin.Model,
    loops: Sequence[Loop],
    pin_joint: np.ndarray,
    com_in_joint: np.ndarray,
) -> tuple[MaximalLoop, ...]:
    """The :class:`MaximalLoop` of each loop (checked by
    :func:`~mbplan.robots.loops.loop_from_spec`; its ``components`` as given, so pass resolved
    loops, e.g. :attr:`~mbplan.robots.Robot.loops`); body ``b`` is moved by Pinocchio joint
    ``pin_joint[b]`` and has its COM at ``com_in_joint[b]``. :class:`InputError` for a loop the
    model cannot hold (unknown kind, joint or row; bad placement; both frames on one body)."""
    body_of = {int(j): b for b, j in enumerate(pin_joint)}
    out = []
    for i, given in enumerate(loops):
        loop = loop_from_spec(model, given, i)
        sides = []
        for joint, M in ((loop.joint1, loop.placement1), (loop.joint2, loop.placement2)):
            jid = model.getJointId(joint)
            if jid == 0:
                sides += [-1, _readonly(M[:3, :3]), _readonly(M[:3, 3])]
                continue
            b = body_of[jid]
            sides += [b, _readonly(M[:3, :3]), _readonly(M[:3, 3] - com_in_joint[b])]
        rows = tuple(int(r) for r in loop.rows)
        out.append(MaximalLoop(loop.name, loop.kind, rows, *sides))
    return tuple(out)


def loop_constraint(
    kind: str,
    rows: Sequence[int],
    R1: Any,
    p1: Any,
    R2: Any,
    p2: Any,
    Rf1: Any,
    r1: Any,
    Rf2: Any,
    r2: Any,
) -> cs.SX:
    """The imposed rows of a ``kind`` closure of bodies at ``(R₁, p₁)``, ``(R₂, p₂)`` whose
    frames sit at ``(Rf, r)`` in them (module docstring), a CasADi expression."""
    full = loop_residual(
        kind,
        cs.mtimes(R1, Rf1),
        p1 + cs.mtimes(R1, r1),
        cs.mtimes(R2, Rf2),
        p2 + cs.mtimes(R2, r2),
        xp=cs,
    )
    return full[list(rows)]


def loop_residuals(loops: Sequence[MaximalLoop], R: npt.ArrayLike, p: npt.ArrayLike) -> np.ndarray:
    """The imposed rows of every loop (stacked) at body poses ``R (…, nb, 3, 3)``,
    ``p (…, nb, 3)``: ``(…, m)``."""
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    lead = R.shape[:-3]
    out = np.zeros((*lead, sum(lp.dim for lp in loops)))
    at = 0
    for lp in loops:
        frames = []
        for b, Rf, r in ((lp.body1, lp.Rf1, lp.r1), (lp.body2, lp.Rf2, lp.r2)):
            if b < 0:
                frames.append((np.broadcast_to(Rf, (*lead, 3, 3)), np.broadcast_to(r, (*lead, 3))))
            else:
                body = R[..., b, :, :]
                frames.append((body @ Rf, p[..., b, :] + body @ r))
        (R1, p1), (R2, p2) = frames
        for idx in np.ndindex(*lead):
            full = loop_residual(lp.kind, R1[idx], p1[idx], R2[idx], p2[idx])
            out[(*idx, slice(at, at + lp.dim))] = full[list(lp.rows)]
        at += lp.dim
    return out


def _readonly(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out
