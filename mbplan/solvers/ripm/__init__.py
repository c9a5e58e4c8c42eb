"""The Riemannian interior point method (RIPM paper, Algorithm 1) with IPOPT's globalization.

:mod:`.driver` runs the iterations with the components, each constructed with its options group
(:mod:`.options`) and called with explicit arguments: :mod:`.phase` (the barrier problem of the
main or a restoration phase: evaluations, trial points, residuals of :mod:`.iterate`'s iterate),
:mod:`.newton` (the Newton step with inertia correction), :mod:`.line_search` (the filter line
search), :mod:`.barrier` (μ and its strategies), :mod:`.restoration` (the soft and ℓ1
restoration phases); :mod:`.output` records the history and the log, :mod:`.kernels` holds the
compiled vector arithmetic of an iteration."""
