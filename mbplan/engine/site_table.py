"""Bound site loops (:class:`~mbplan.engine.jit.SiteLoop`) called from compiled code: a table of
their C entry points and argument arrays, run by one numba call instead of one ctypes call per
term (each loop reads and writes the same memory as its Python call)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numba as nb
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from mbplan.engine.jit import _BoundLoop


@intrinsic
def _call_site_loop(typingctx, address, sites, args, res):  # pragma: no cover - compiled
    """``int loop(casadi_int K, const double** arg, double** res)`` at ``address`` (the
    signature of every site loop's C entry point)."""
    sig = types.int32(types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, values):
        pointer = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.IntType(32), [ir.IntType(64), pointer, pointer])
        fn = builder.inttoptr(values[0], fnty.as_pointer())
        arg, out = (builder.inttoptr(v, pointer) for v in values[2:])
        return builder.call(fn, [values[1], arg, out])

    return sig, codegen


@nb.njit(cache=True)
def run_site_loops(table: np.ndarray) -> int:  # pragma: no cover - compiled
    """Call every row ``(entry point, sites, argument pointers, result pointers)`` of ``table``
    in order; the index of the first loop that reports a failure, or -1."""
    for i in range(table.shape[0]):
        if _call_site_loop(table[i, 0], table[i, 1], table[i, 2], table[i, 3]):
            return i
    return -1


def site_table(calls: Sequence[Callable[[], None]]) -> np.ndarray | None:
    """The table of ``calls`` for :func:`run_site_loops` (read-only; it points into memory the
    calls keep alive), or ``None`` if one of them is not a compiled site loop."""
    if not all(type(c) is _BoundLoop for c in calls):
        return None
    rows = [c.table_row() for c in calls]
    table = np.array(rows, dtype=np.int64).reshape(len(rows), 4)
    table.setflags(write=False)
    return table


SITE_TABLE_KERNELS = (run_site_loops,)  # compiled entry points (for the cache check)
