"""Call CasADi Functions on NumPy arrays through preallocated buffers (no DM conversion).

A ``(K, m)`` C-ordered array is the column-major ``m x K`` matrix CasADi expects for a K-fold
``map``/``mapaccum``, so inputs and outputs pass by memoryview without copies.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.engine.jit import compile_function, jit_available


class BufferedFunction:
    """``f(*arrays) -> list[np.ndarray]`` with outputs shaped ``(size2, size1)`` (C order)."""

    def __init__(self, fn: cs.Function, *, jit: bool = True) -> None:
        self.fn = compile_function(fn) if jit and jit_available() else fn
        self._buf, self._eval = self.fn.buffer()
        self._in_shapes = [
            (self.fn.size2_in(i), self.fn.size1_in(i)) for i in range(self.fn.n_in())
        ]
        self._out_shapes = [
            (self.fn.size2_out(i), self.fn.size1_out(i)) for i in range(self.fn.n_out())
        ]
        self._keep: list[np.ndarray] = []

    def __call__(self, *arrays: np.ndarray) -> list[np.ndarray]:
        keep = []
        for i, (a, shape) in enumerate(zip(arrays, self._in_shapes, strict=True)):
            a = np.ascontiguousarray(a, dtype=float)
            if a.size != shape[0] * shape[1]:
                raise ValueError(f"{self.fn.name()} input {i}: {a.shape} does not match {shape}")
            keep.append(a)
            self._buf.set_arg(i, memoryview(a.reshape(-1)))
        outs = [np.empty(shape) for shape in self._out_shapes]
        for i, o in enumerate(outs):
            self._buf.set_res(i, memoryview(o.reshape(-1)))
        self._eval()
        self._keep = keep
        return outs
