"""Trajectory variables: named blocks of group elements per knot, some knots held fixed.

A block holds ``count`` elements per knot (e.g. one per rigid body). A point is a ``dict`` mapping
block names to arrays ``(knots, *element_shape)`` (``count == 1``) or ``(knots, count,
*element_shape)``. Elements are addressed by the flat index ``knot * count + element``. The
tangent space is R^n: the free elements' tangent coordinates stacked block by block.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mbplan.errors import InputError
from mbplan.finite import finite_vector
from mbplan.transcription.packed import PackedLayout, PackedPoint
from mbplan.workspace import Workspace, shared

Point = dict[str, np.ndarray]


@dataclass(frozen=True)
class Block:
    """``knots × count`` elements of ``group``; the knots in ``fixed`` are data, not variables."""

    name: str
    group: Any
    knots: int
    fixed: tuple[int, ...] = field(default=())
    count: int = 1

    def __post_init__(self) -> None:
        # any sequence of knots (a list, an array) as a tuple of ints: blocks are workspace keys
        object.__setattr__(self, "fixed", tuple(int(k) for k in self.fixed))

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of the block's array in a point."""
        per_knot = () if self.count == 1 else (self.count,)
        return (self.knots, *per_knot, *self.group.element_shape)

    def flat(self, a: np.ndarray) -> np.ndarray:
        """The block's array as ``(knots * count, *element_shape)``."""
        return a.reshape(self.knots * self.count, *self.group.element_shape)


class TrajectoryVariables:
    """Layout of the tangent space of a product of per-knot group elements."""

    def __init__(self, blocks: Iterable[Block]) -> None:
        self.blocks = {b.name: b for b in blocks}
        offset = 0
        self._index: dict[str, np.ndarray] = {}
        self._free: list[tuple[Block, np.ndarray, np.ndarray]] = []  # blocks with free knots
        for b in self.blocks.values():
            if any(not 0 <= k < b.knots for k in b.fixed):
                raise InputError(
                    f"block {b.name!r}: fixed knots {b.fixed} outside 0..{b.knots - 1}"
                )
            free = np.ones((b.knots, b.count), dtype=bool)
            free[list(b.fixed)] = False
            free = free.ravel()
            idx = -np.ones((b.knots * b.count, b.group.dim), dtype=np.int64)
            nfree = int(free.sum())
            idx[free] = offset + np.arange(nfree * b.group.dim).reshape(nfree, b.group.dim)
            offset += nfree * b.group.dim
            idx.setflags(write=False)  # shared by every problem of these variables
            self._index[b.name] = idx
            if nfree:
                self._free.append((b, _as_slice(free), _as_slice(idx[free])))
        self.n = offset
        # free blocks of one matrix group (e.g. every SO(3) block) retract in one batched call;
        # per block: name, flat and point shapes, free elements, their tangent columns
        by_group: dict[int, list] = {}
        for b, free, cols in self._free:
            key = id(b.group) if len(b.group.element_shape) == 2 else id(b)
            flat = (b.knots * b.count, *b.group.element_shape)
            by_group.setdefault(key, []).append((b.name, flat, b.shape, free, cols))
        self._retract_groups = [
            (self.blocks[entries[0][0]].group, entries) for entries in by_group.values()
        ]
        self.layout = PackedLayout(list(self.blocks.values()), self._index)

    def tangent_index(self, name: str) -> np.ndarray:
        """``(knots * count, dim)`` tangent coordinates of each element; ``-1`` where fixed."""
        return self._index[name]

    def check_point(self, point: Mapping[str, np.ndarray], what: str = "point") -> Point:
        """Validate shapes, finiteness and group membership; return float copies."""
        out: Point = {}
        for b in self.blocks.values():
            if b.name not in point:
                raise InputError(f"{what}: missing block {b.name!r}")
            a = np.array(point[b.name], dtype=float)
            if a.shape != b.shape:
                raise InputError(
                    f"{what}: block {b.name!r} must have shape {b.shape}, got {a.shape}"
                )
            b.group.check(a)  # raises InputError naming the problem (NaN, not in group, ...)
            out[b.name] = a
        extra = sorted(set(point) - set(self.blocks))
        if extra:
            raise InputError(f"{what}: unknown blocks {extra}")
        return out

    def packed(self, point: Point) -> np.ndarray:
        """The point's blocks raveled into one vector (shapes and finiteness checked): the
        vector of a :class:`PackedPoint` itself, without a copy."""
        if type(point) is PackedPoint and point.packed_by(self.layout):
            vec = point.packed
        else:
            parts = []
            mapping = type(point) is dict or isinstance(point, Mapping)
            for b in self.blocks.values():
                a = point.get(b.name) if mapping else None
                if a is None or np.shape(a) != b.shape:
                    got = "missing" if a is None else f"shape {np.shape(a)}"
                    raise InputError(
                        f"point: block {b.name!r} must have shape {b.shape}, got {got}"
                    )
                parts.append(np.asarray(a, dtype=float).reshape(-1))
            vec = np.concatenate(parts)
        if not finite_vector(vec):
            bad = next(n for n in self.blocks if not np.isfinite(point[n]).all())
            raise InputError(f"point: block {bad!r} contains NaN or inf")
        return vec

    def retract(self, point: Point, dx: np.ndarray) -> Point:
        """``X exp(ξ)`` on every free element (``y + ξ`` for vector blocks): a
        :class:`PackedPoint` from one compiled pass when every free block is SO(3) or Rⁿ and
        the inputs pass the groups' checks, the blocks one group at a time otherwise."""
        layout = self.layout
        if layout.retractable and type(dx) is np.ndarray and dx.shape == (self.n,):
            packed = layout.pack(point) if dx.dtype == np.float64 else None
            out = None if packed is None else layout.retract(packed, dx)
            if out is not None:
                return layout.unpack(out)
        return self._retract_blocks(point, dx)

    def _retract_blocks(self, point: Point, dx: np.ndarray) -> Point:
        """The retraction by the groups' ``retract`` (any group; their errors)."""
        out = dict(point)
        for group, entries in self._retract_groups:
            flats = [point[name].reshape(flat) for name, flat, _, _, _ in entries]
            Xs = [f[e[3]] for f, e in zip(flats, entries, strict=True)]
            xis = [dx[e[4]].reshape(-1, group.dim) for e in entries]
            if len(entries) == 1:
                moved = [group.retract(Xs[0], xis[0])]
            else:
                Y = group.retract(np.concatenate(Xs), np.concatenate(xis))
                moved, start = [], 0
                for X in Xs:
                    moved.append(Y[start : start + len(X)])
                    start += len(X)
            for (name, _, shape, free, _), flat, Y in zip(entries, flats, moved, strict=True):
                new = flat.copy()
                new[free] = Y
                out[name] = new.reshape(shape)
        return out

    def local(self, point: Point, other: Point) -> np.ndarray:
        """Inverse of :meth:`retract`: the tangent vector from ``point`` to ``other``."""
        dx = np.zeros(self.n)
        for b in self.blocks.values():
            idx = self._index[b.name]
            free = idx[:, 0] >= 0
            if free.any():
                dx[idx[free]] = b.group.local(
                    b.flat(point[b.name])[free], b.flat(other[b.name])[free]
                )
        return dx


def trajectory_variables(
    blocks: Iterable[Block], workspace: Workspace | None = None
) -> TrajectoryVariables:
    """``TrajectoryVariables(blocks)``, kept in ``workspace`` by the blocks: a layout without
    values, shared by every problem of a task family."""
    blocks = tuple(blocks)
    return shared(workspace, "variables", lambda: blocks, lambda: TrajectoryVariables(blocks))


def _as_slice(index: np.ndarray) -> slice | np.ndarray:
    """A boolean mask or an integer index array as the equivalent slice when it selects one
    contiguous run (``a[slice]`` is a view: no gather on every retraction), else unchanged."""
    flat = np.flatnonzero(index) if index.dtype == bool else index.ravel()
    if flat.size and np.array_equal(flat, np.arange(flat[0], flat[0] + flat.size)):
        return slice(int(flat[0]), int(flat[0]) + flat.size)
    return index
