"""Points of trajectory variables as one vector, and their retraction in one compiled pass.

The *packed* vector of a point is every block's array raveled and concatenated in block order:
what the problem's term inputs are gathered from. A :class:`PackedPoint` is a point whose arrays
are views into its packed vector, so evaluating it needs no concatenation; the retraction makes
them. :meth:`PackedLayout.retract` moves every free SO(3) and Rⁿ element of a packed vector in
one pass (``X exp(ξ)`` with :mod:`mbplan.lie.so3_kernels`, ``y + ξ``): bit for bit what the
groups' own ``retract`` give, with their checks (finite, ``X`` a rotation) as flags.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from operator import is_
from typing import Any

import numba as nb
import numpy as np

from mbplan.lie.group import MEMBERSHIP_TOL, rotation_error
from mbplan.lie.rn import RnGroup
from mbplan.lie.so3 import SO3Group
from mbplan.lie.so3_kernels import exp_into, product_into


class PackedPoint(dict):
    """A point (block name → array) whose arrays are views into the vector ``packed`` of a
    :class:`PackedLayout`; writing into an array writes into ``packed``. Copies and pickles
    are plain dicts."""

    def __init__(self, layout: PackedLayout, packed: np.ndarray) -> None:
        views = [packed[a:b].reshape(shape) for a, b, shape in layout.slots]
        super().__init__(zip(layout.names, views, strict=True))
        self.layout, self.packed, self._views = layout, packed, views

    def packed_by(self, layout: PackedLayout) -> bool:
        """Made by ``layout`` and every block still its view (none replaced or re-inserted:
        the values in insertion order are the views)."""
        views = self._views
        return (
            self.layout is layout
            and len(self) == len(views)
            and all(map(is_, self.values(), views))
        )

    def __reduce__(self) -> tuple:
        return (dict, (dict(self),))

    def __copy__(self) -> dict:
        return dict(self)


class PackedLayout:
    """Where every block lives in the packed vector, and the free elements the compiled
    retraction moves (``retractable``: every free block is SO(3) or Rⁿ)."""

    def __init__(self, blocks: Sequence[Any], index: Mapping[str, np.ndarray]) -> None:
        self.names = [b.name for b in blocks]
        self.slots: list[tuple[int, int, tuple[int, ...]]] = []
        so3_off, so3_col, rn_dst, rn_src = [], [], [], []
        self.retractable, start = True, 0
        for b in blocks:
            size = int(np.prod(b.shape))
            self.slots.append((start, start + size, b.shape))
            idx = index[b.name]  # (elements, dim) tangent columns, -1 where fixed
            free = np.flatnonzero(idx[:, 0] >= 0)
            width = size // (b.knots * b.count)  # entries per element
            if free.size and isinstance(b.group, SO3Group):
                so3_off.append(start + 9 * free)
                so3_col.append(idx[free, 0])
            elif free.size and isinstance(b.group, RnGroup):
                rn_dst.append((start + width * free[:, None] + np.arange(width)).ravel())
                rn_src.append(idx[free].ravel())
            elif free.size:
                self.retractable = False
            start += size

        def cat(parts: list[np.ndarray]) -> np.ndarray:
            return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)

        self._so3_off, self._so3_col = cat(so3_off), cat(so3_col)
        self._rn_dst, self._rn_src = cat(rn_dst), cat(rn_src)

    def pack(self, point: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """The packed vector of ``point`` (``packed`` itself for a :class:`PackedPoint` of
        this layout), or ``None`` if a block is missing, of another shape or not float64, or
        the point has other keys (the callers' general paths name the problem)."""
        if type(point) is PackedPoint and point.packed_by(self):
            return point.packed
        if len(point) != len(self.names):
            return None
        parts = []
        for name, (_, _, shape) in zip(self.names, self.slots, strict=True):
            a = point.get(name)
            if type(a) is not np.ndarray or a.shape != shape or a.dtype != np.float64:
                return None
            parts.append(a.reshape(-1))
        return np.concatenate(parts)

    def unpack(self, packed: np.ndarray) -> PackedPoint:
        return PackedPoint(self, packed)

    def retract(self, packed: np.ndarray, dx: np.ndarray) -> np.ndarray | None:
        """The packed ``R_x(dx)``, or ``None`` if ``x`` or ``dx`` is not finite, a rotation
        is not one (the groups' membership check) or the result is not finite."""
        out = np.empty_like(packed)
        err, det_min, finite = _retract(
            packed, dx, self._so3_off, self._so3_col, self._rn_dst, self._rn_src, out
        )
        if not finite or err > MEMBERSHIP_TOL or det_min <= 0:
            return None
        return out


@nb.njit(cache=True)
def _retract(x, dx, so3_off, so3_col, rn_dst, rn_src, out):  # pragma: no cover - compiled
    """``out = x`` with every listed SO(3) element ``X exp(ξ)`` and Rⁿ entry ``y + ξ``;
    returns the largest ``|XᵀX - I|``, the smallest ``det X`` and whether ``x`` (moved
    elements), ``dx`` and ``out`` are finite."""
    finite = True
    for i in range(x.shape[0]):
        out[i] = x[i]
    for q in range(rn_dst.shape[0]):
        v = x[rn_dst[q]] + dx[rn_src[q]]
        finite &= np.isfinite(v)  # ∞ + finite, NaN in x or dx, or an overflow
        out[rn_dst[q]] = v
    err, det_min = 0.0, np.inf
    for k in range(so3_off.shape[0]):
        o, c = so3_off[k], so3_col[k]
        for i in range(9):
            finite &= np.isfinite(x[o + i])
        for i in range(3):
            finite &= np.isfinite(dx[c + i])
        e, d = rotation_error(x, o)
        err, det_min = max(err, e), min(det_min, d)
        exp_into(dx[c], dx[c + 1], dx[c + 2], out, o)
        product_into(x, o, out, o, out, o)
        for i in range(9):
            finite &= np.isfinite(out[o + i])
    return err, det_min, finite
