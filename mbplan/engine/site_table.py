"""Bound site loops (:class:`~mbplan.engine.jit.BoundLoop`) called from compiled code: a table of
their C entry points and argument arrays, run by one numba call instead of one ctypes call per
term (each loop reads and writes the same memory as its Python call)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numba as nb
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from mbplan.engine.jit import BoundLoop


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


@nb.njit(cache=True, nogil=True)
def run_site_loops(table: np.ndarray) -> int:  # pragma: no cover - compiled
    """Call every row ``(entry point, sites, argument pointers, result pointers)`` of ``table``
    in order, up to the first loop that reports a failure; its index, or -1."""
    for i in range(table.shape[0]):
        if _call_site_loop(table[i, 0], table[i, 1], table[i, 2], table[i, 3]):
            return i
    return -1


class SiteTable:
    """Bound site loops run in order by one compiled call (:func:`run_site_loops`); it keeps
    the calls, whose memory the table's addresses point into."""

    def __init__(self, calls: Sequence[BoundLoop]) -> None:
        self.calls = tuple(calls)
        self.rows = np.array([c.table_row() for c in self.calls], np.int64).reshape(-1, 4)
        self.rows.setflags(write=False)

    def __call__(self) -> None:
        """Run every loop; a failing one raises its call's error (the later ones do not run)."""
        failed = run_site_loops(self.rows)
        if failed >= 0:
            raise self.calls[failed].failure()


class CallsInOrder:
    """Calls run one after the other."""

    def __init__(self, calls: Sequence[Callable[[], None]]) -> None:
        self.calls = tuple(calls)

    def __call__(self) -> None:
        for call in self.calls:
            call()


def bound_calls(calls: Sequence[Callable[[], None]]) -> Callable[[], None]:
    """One call running every call (each writes only its own outputs, so in any order): the
    compiled site loops by one :class:`SiteTable`, the others (interpreted CasADi buffers,
    callbacks) one by one."""
    loops = [c for c in calls if type(c) is BoundLoop]
    others = [c for c in calls if type(c) is not BoundLoop]
    if not loops:
        return CallsInOrder(others)
    return SiteTable(loops) if not others else CallsInOrder([SiteTable(loops), *others])
