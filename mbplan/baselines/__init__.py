"""Baseline trajectory optimizers the RIPM is compared with (RIPM paper §VIII)."""

from mbplan.baselines.quaternion_ipopt import QuaternionIpoptResult, solve_quaternion_ipopt

__all__ = ["QuaternionIpoptResult", "solve_quaternion_ipopt"]
