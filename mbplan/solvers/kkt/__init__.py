"""The RIPM's KKT systems: the pattern of the matrix (:mod:`.pattern`), its assembly and
inertia-revealing factorization (:mod:`.system`), fill-reducing orderings (:mod:`.ordering`), the
supernodal LDLᵀ (:mod:`.ldl`) and the joint-eliminated (reduced) system (:mod:`.reduced`)."""
