"""Interior point methods in Lie-algebra coordinates: MLG-IPM (Santos et al., Alg. 1;
:mod:`.mlgipm`) and Lai & Yoshise's globally convergent RIPM (:mod:`.lai_yoshise`), on the
primal-dual KKT vector field they share (:mod:`.kkt_field`)."""
