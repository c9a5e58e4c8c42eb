"""The KKT system with the joint constraints eliminated by exact per-knot congruences:
``inertia(K) = inertia(K_reduced) + (m, m, 0)``. :mod:`.system` is the solver-facing object,
:mod:`.reduction` the congruences, :mod:`.symbolic` and :mod:`.layout` their symbolic phase,
:mod:`.kernels`, :mod:`.products` and :mod:`.solves` the compiled numeric work."""
