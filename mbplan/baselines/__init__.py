"""Baseline trajectory optimizers the RIPM is compared with (RIPM paper §VIII): IPOPT's shared
options and statistics (:mod:`mbplan.baselines.ipopt`) and the embedded-manifold IPOPT of the
MLG-IPM study (:mod:`mbplan.baselines.embedded_ipopt`)."""
