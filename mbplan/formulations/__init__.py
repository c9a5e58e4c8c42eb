"""Translations of an :class:`mbplan.OCP` into the NLP of one formulation: generalized
coordinates (:mod:`.generalized`, Pinocchio + IPOPT) and maximal coordinates (:mod:`.maximal`,
SO(3)×R³ bodies, LGVI, RIPM). Each residual kind is written once per formulation here."""
