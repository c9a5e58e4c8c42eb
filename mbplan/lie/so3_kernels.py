"""Compiled SO(3) arithmetic on batches: Rodrigues' ``exp`` and 3 × 3 products in one fixed
order, shared by :class:`~mbplan.lie.so3.SO3Group` and the packed retraction of trajectory
variables (:mod:`mbplan.transcription.packed`), so both give the same bits.

A product entry is ``fma(a₂, b₂, fma(a₁, b₁, fma(a₀, b₀, 0)))``: the order of OpenBLAS's
``dgemm`` kernel on the machines these were measured on (NumPy's ``A @ B`` for 3 × 3 batches
there, bit for bit, signed zeros, infinities and NaN included), written out so it no longer
depends on the BLAS. ``exp(φ) = (I + a φ^) + b φ^φ^`` with ``a = sinθ/θ``,
``b = (1-cosθ)/θ²`` (Taylor series for ``θ² < SMALL``).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

SMALL = 1e-6
"""θ² below which the Taylor series replace the closed forms of ``a`` and ``b``."""


@intrinsic
def _fma(typingctx, a, b, c):  # pragma: no cover - compiled
    """``a·b + c`` with one rounding (LLVM's ``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@nb.njit(inline="always")
def dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``a · b`` of two 3-vectors in the fixed order of the module docstring."""
    return _fma(a2, b2, _fma(a1, b1, _fma(a0, b0, 0.0)))


@nb.njit(inline="always")
def coefficients(x, y, z):  # pragma: no cover - compiled
    """``a = sinθ/θ``, ``b = (1-cosθ)/θ²`` of ``φ = (x, y, z)``."""
    t2 = x * x + y * y + z * z
    if t2 < SMALL:
        return 1 - t2 / 6 + t2 * t2 / 120, 0.5 - t2 / 24 + t2 * t2 / 720
    t = np.sqrt(t2)
    return np.sin(t) / t, (1 - np.cos(t)) / (t * t)


@nb.njit(inline="always")
def exp_into(x, y, z, out, o):  # pragma: no cover - compiled
    """``exp(φ)`` of ``φ = (x, y, z)``, row-major into ``out[o : o + 9]``."""
    a, b = coefficients(x, y, z)
    # φ^ = [[0, -z, y], [z, 0, -x], [-y, x, 0]] (zeros +0.0) and the products of its rows and
    # columns
    k01, k02, k10, k12, k20, k21 = -z, y, z, -x, -y, x
    out[o + 0] = (1.0 + a * 0.0) + b * dot3(0.0, k01, k02, 0.0, k10, k20)
    out[o + 1] = (0.0 + a * k01) + b * dot3(0.0, k01, k02, k01, 0.0, k21)
    out[o + 2] = (0.0 + a * k02) + b * dot3(0.0, k01, k02, k02, k12, 0.0)
    out[o + 3] = (0.0 + a * k10) + b * dot3(k10, 0.0, k12, 0.0, k10, k20)
    out[o + 4] = (1.0 + a * 0.0) + b * dot3(k10, 0.0, k12, k01, 0.0, k21)
    out[o + 5] = (0.0 + a * k12) + b * dot3(k10, 0.0, k12, k02, k12, 0.0)
    out[o + 6] = (0.0 + a * k20) + b * dot3(k20, k21, 0.0, 0.0, k10, k20)
    out[o + 7] = (0.0 + a * k21) + b * dot3(k20, k21, 0.0, k01, 0.0, k21)
    out[o + 8] = (1.0 + a * 0.0) + b * dot3(k20, k21, 0.0, k02, k12, 0.0)


@nb.njit(inline="always")
def product_into(a, ia, b, ib, out, o):  # pragma: no cover - compiled
    """``A B`` of the row-major 3 × 3 matrices ``a[ia : ia + 9]``, ``b[ib : ib + 9]`` into
    ``out[o : o + 9]`` (``out`` may be either input's array at the same place)."""
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = (
        b[ib], b[ib + 1], b[ib + 2], b[ib + 3], b[ib + 4], b[ib + 5], b[ib + 6], b[ib + 7],
        b[ib + 8],
    )  # fmt: skip
    for i in range(3):
        r0, r1, r2 = a[ia + 3 * i], a[ia + 3 * i + 1], a[ia + 3 * i + 2]
        out[o + 3 * i] = dot3(r0, r1, r2, b0, b3, b6)
        out[o + 3 * i + 1] = dot3(r0, r1, r2, b1, b4, b7)
        out[o + 3 * i + 2] = dot3(r0, r1, r2, b2, b5, b8)


@nb.njit(cache=True)
def exp_batch(xi: np.ndarray) -> np.ndarray:
    """``exp`` of every row of the ``(n, 3)`` array ``xi``: ``(n, 3, 3)``."""
    n = xi.shape[0]
    out = np.empty(9 * n)
    for k in range(n):
        exp_into(xi[k, 0], xi[k, 1], xi[k, 2], out, 9 * k)
    return out.reshape(n, 3, 3)


@nb.njit(cache=True)
def product_batch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a[k] @ b[k]`` for two C-contiguous ``(n, 3, 3)`` arrays."""
    n = a.shape[0]
    fa, fb = a.reshape(9 * n), b.reshape(9 * n)
    out = np.empty(9 * n)
    for k in range(n):
        product_into(fa, 9 * k, fb, 9 * k, out, 9 * k)
    return out.reshape(n, 3, 3)
