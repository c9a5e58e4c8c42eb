"""Loop closures in the multi-body transcription (RIPM paper eq. 27–28, :mod:`.multibody`).

A closure (:mod:`mbplan.multibody.loops`) is a constraint between two bodies like a joint's, so
the LGVI treats it like one: its multipliers ``λ_{k+1}`` (one per imposed row) add the forces
``J(x_{k+1})ᵀλ_{k+1}`` (:func:`~mbplan.dynamics.joints.constraint_forces`) into both bodies'
dynamics rows of step ``k`` and the closure holds on the next configuration,
``h(R_{k+1} F_{k+1}, p_{k+1} + v_{k+1} Δt) = 0``. Knot 0's multipliers are data.

Blocks: ``loop_lam{d}`` (``R^d``) holds the multipliers of the loops with ``d`` imposed rows
(:data:`LOOP_BLOCK` ``.format(d)``, in the order of ``mm.loops``). Terms: per loop group (kind,
imposed rows, which side is the world: :attr:`~mbplan.multibody.loops.MaximalLoop.group`) one
forces and one constraint term over (knot, loop) sites.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics.joints import constraint_forces
from mbplan.engine import RiemannianFunction
from mbplan.lie import SO3, R
from mbplan.multibody import MaximalModel
from mbplan.multibody.loops import MaximalLoop, loop_constraint
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block

LOOP_BLOCK = "loop_lam{}"
"""Name of the block of the multipliers of the loops with a given number of imposed rows."""

_FRAMES = [("Rf1", (3, 3)), ("r1", 3), ("Rf2", (3, 3)), ("r2", 3)]
Group = tuple[str, tuple[int, ...], bool, bool]


def _moving(group: Group) -> tuple[str, ...]:
    """The sides (``"1"``, ``"2"``) of a loop group that are bodies, not the world."""
    return tuple(s for s, world in (("1", group[2]), ("2", group[3])) if not world)


def _name(group: Group, what: str) -> str:
    kind, rows, world1, world2 = group
    side = "_world1" if world1 else "_world2" if world2 else ""
    return f"loop_{kind}_{''.join(map(str, rows))}_{what}{side}"


def _closure(group: Group) -> Callable[..., cs.SX]:
    """``h(pose₁…)`` of the moving sides' ``(R, p)`` (the world's is ``(I, 0)``) and frames."""
    kind, rows = group[0], group[1]
    moving = _moving(group)

    def h(*poses: cs.SX, Rf1, r1, Rf2, r2) -> cs.SX:
        it = iter(poses)
        world = (cs.DM.eye(3), cs.DM.zeros(3))
        side = {s: (next(it), next(it)) if s in moving else world for s in "12"}
        return loop_constraint(kind, rows, *side["1"], *side["2"], Rf1, r1, Rf2, r2)

    return h


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def loop_forces_function(jit: bool, group: Group) -> RiemannianFunction:
    """``J(x_{k+1})ᵀλ_{k+1}`` of a closure into its moving bodies' dynamics rows (rotational,
    translational per body; the sign of :func:`~mbplan.dynamics.joints.revolute_forces`)."""
    moving = _moving(group)
    variables = [v for s in moving for v in ((f"R{s}", SO3), (f"p{s}", R(3)))]
    variables.append(("lam", R(len(group[1]))))
    h = _closure(group)

    def fn(lam, Rf1, r1, Rf2, r2, **x):
        bodies = [(x[f"R{s}"], x[f"p{s}"]) for s in moving]
        forces = constraint_forces(lambda *y: h(*y, Rf1=Rf1, r1=r1, Rf2=Rf2, r2=r2), bodies, lam)
        return cs.vertcat(*(-part for pair in forces for part in pair))

    return RiemannianFunction(_name(group, "forces"), variables, fn, _FRAMES, jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def loop_constraint_function(jit: bool, group: Group) -> RiemannianFunction:
    """``h(x_{k+1})`` with ``x_{k+1} = (R_k F_k, p_k + v_k Δt)`` for the moving bodies."""
    moving = _moving(group)
    names = (("R", SO3), ("F", SO3), ("p", R(3)), ("v", R(3)))
    variables = [(f"{n}{s}", g) for s in moving for n, g in names]
    h = _closure(group)

    def fn(dt, Rf1, r1, Rf2, r2, **x):
        nxt = []
        for s in moving:
            nxt += [cs.mtimes(x[f"R{s}"], x[f"F{s}"]), x[f"p{s}"] + x[f"v{s}"] * dt]
        return h(*nxt, Rf1=Rf1, r1=r1, Rf2=Rf2, r2=r2)

    params = [*_FRAMES, ("dt", 1)]
    return RiemannianFunction(_name(group, "constraints"), variables, fn, params, jit=jit)


def loop_blocks(mm: MaximalModel, N: int) -> list[Block]:
    """The multiplier blocks (module docstring), knot 0 fixed."""
    dims = sorted({lp.dim for lp in mm.loops})
    count = {d: sum(lp.dim == d for lp in mm.loops) for d in dims}
    return [Block(LOOP_BLOCK.format(d), R(d), N + 1, (0,), count[d]) for d in dims]


def loop_elements(loops: tuple[MaximalLoop, ...]) -> np.ndarray:
    """Each loop's element in its multiplier block (its rank among the loops of its size)."""
    dims = np.array([lp.dim for lp in loops], dtype=np.int64)
    return np.array([np.sum(dims[:i] == d) for i, d in enumerate(dims)], dtype=np.int64)


def loop_terms(
    mm: MaximalModel, N: int, dt: float, jit: bool, dyn_rows: Callable[..., np.ndarray]
) -> list[Term]:
    """The forces and constraint terms of every loop group (module docstring);
    ``dyn_rows(step, body)``: the ``(K, 6)`` dynamics rows of bodies at steps."""
    loops = mm.loops
    element = loop_elements(loops)
    groups: dict[Group, list[int]] = {}
    for i, lp in enumerate(loops):
        groups.setdefault(lp.group, []).append(i)
    terms = []
    for group, members in groups.items():
        kk, ii = (a.ravel() for a in np.meshgrid(np.arange(N), members, indexing="ij"))
        nxt = (kk + 1) * mm.nb
        block = LOOP_BLOCK.format(len(group[1]))
        params = {name: np.array([getattr(loops[i], name) for i in ii]) for name, _ in _FRAMES}
        body = {s: np.array([getattr(loops[i], f"body{s}") for i in ii]) for s in "12"}
        moving = _moving(group)
        count = sum(lp.dim == len(group[1]) for lp in loops)
        forces = {"lam": (block, (kk + 1) * count + element[ii])}
        cons = {}
        for s in moving:
            forces |= {f"R{s}": ("R", nxt + body[s]), f"p{s}": ("p", nxt + body[s])}
            cons |= {f"{n}{s}": (n, nxt + body[s]) for n in ("R", "F", "p", "v")}
        rows = np.concatenate([dyn_rows(kk, body[s]) for s in moving], axis=1)
        fn = loop_forces_function(jit, group)
        terms.append(Term(_name(group, "forces"), "eq", fn, forces, params, rows=rows))
        fn = loop_constraint_function(jit, group)
        terms.append(Term(_name(group, "constraints"), "eq", fn, cons, params | {"dt": dt}))
    return terms


def stack_multipliers(mm: MaximalModel, point: dict[str, np.ndarray], knots: int) -> np.ndarray:
    """Every loop's multipliers ``(knots, m)`` (loops in ``mm.loops`` order) from ``point``'s
    blocks."""
    element = loop_elements(mm.loops)
    parts = [np.zeros((knots, 0))]
    for lp, e in zip(mm.loops, element, strict=True):
        block = np.asarray(point[LOOP_BLOCK.format(lp.dim)]).reshape(knots, -1, lp.dim)
        parts.append(block[:, e])
    return np.concatenate(parts, axis=1)


def multiplier_blocks(mm: MaximalModel, lam: np.ndarray) -> dict[str, np.ndarray]:
    """The blocks of :func:`loop_blocks` (point arrays) holding ``lam (knots, m)``, the inverse
    of :func:`stack_multipliers`."""
    lam = np.asarray(lam, dtype=float)
    blocks = loop_blocks(mm, len(lam) - 1)
    out = {b.name: np.zeros((len(lam), b.count, b.group.dim)) for b in blocks}
    at = 0
    for lp, e in zip(mm.loops, loop_elements(mm.loops), strict=True):
        out[LOOP_BLOCK.format(lp.dim)][:, e] = lam[:, at : at + lp.dim]
        at += lp.dim
    return {b.name: out[b.name].reshape(b.shape) for b in blocks}
