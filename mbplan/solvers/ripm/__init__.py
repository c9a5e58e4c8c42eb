"""The Riemannian interior point method (RIPM paper, Algorithm 1) with IPOPT's globalization.

:mod:`.driver` runs the iterations; :mod:`.iterate` holds the primal-dual point and its
residuals, :mod:`.newton` the Newton step with inertia correction, :mod:`.line_search` the
filter line search, :mod:`.barrier` the barrier strategies, :mod:`.restoration` the feasibility
restoration phase, :mod:`.options` the parameters and :mod:`.kernels` the compiled vector
arithmetic of an iteration."""
