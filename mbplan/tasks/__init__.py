"""Every task mbplan ships, as plain data (OCPs, problems and their seeded samplers):
:mod:`.paper` (the RIPM paper's iiwa and drone OCPs), :mod:`.drone` (drone docking cases and
the cluttered scene), :mod:`.lie_ipm` (the MLG-IPM paper's problems on SO(n)² and SL(n)²),
:mod:`.ilqr` (the Lie-group iLQR thesis' scenarios), :mod:`.speed` (the speed benchmark's
iiwa, drone and chain problems), :mod:`.arm_sweep` (reach tasks for every bundled arm) and
:mod:`.mechanisms` (the closed-loop mechanisms' example tasks and their randomizations)."""
