"""Borrowed arrays for the LDLᵀ kernels: a view of an array that holds no reference to its
memory, so that numba emits no reference counting for it.

numba counts references to every array it passes to a function, inlined or not (an atomic
increment and decrement per array and call); its pruning pass removes the pairs only in
straight-line code. In the kernels' loops over thousands of small fronts that is most of the
time of a front with a few columns. A borrowed view has a null ``meminfo``: LLVM folds the
counting away. It must not outlive the array it borrows from, so the kernels borrow only their
arguments (alive for the whole call) and never return a borrowed array.
"""

from __future__ import annotations

from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def borrowed(typingctx, arr):
    """``arr``'s data, shape and strides without its ``meminfo`` (and Python parent)."""

    def codegen(context, builder, sig, args):
        src = context.make_array(sig.args[0])(context, builder, value=args[0])
        out = context.make_array(sig.return_type)(context, builder)
        out.meminfo = cgutils.get_null_value(src.meminfo.type)
        out.parent = cgutils.get_null_value(src.parent.type)
        out.nitems = src.nitems
        out.itemsize = src.itemsize
        out.data = src.data
        out.shape = src.shape
        out.strides = src.strides
        return out._getvalue()

    return arr(arr), codegen
