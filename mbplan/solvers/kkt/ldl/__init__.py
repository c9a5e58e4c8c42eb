"""Supernodal multifrontal LDLᵀ with inertia: symbolic analysis (:mod:`.symbolic`) once per
pattern, compiled numeric kernels (:mod:`.kernels`, :mod:`.dense`, :mod:`.pivot`), triangular
solves (:mod:`.solve`) and the numeric factorization object (:mod:`.supernodal`)."""
