"""Planning: an OCP → a formulation's NLP → a solver (a method of :data:`solve.METHODS`) → one
result type; warm starts in :mod:`.initial_guess`."""
