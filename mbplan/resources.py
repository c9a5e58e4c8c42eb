"""Memory a planning request will need, checked against the memory available before allocating.

The per-knot costs are measured peaks (``ru_maxrss``) of ``plan(iiwa_obstacle(N=...), method,
max_iter=2)`` for the iiwa (7 bodies) at N = 40, 320 and 1280 (RIPM 307, 722, 2032 MB; IPOPT
203, 232, 329 MB): the RIPM's sparse KKT systems and CasADi evaluations grow by about 1.4 MB per
knot, IPOPT's (generalized coordinates) by about 0.1 MB.
The RIPM's cost per knot is scaled by ``(bodies / 7)²`` (the coupling blocks of a chain), so the
estimate errs high for long chains. ``MBPLAN_MEMORY_LIMIT_GB`` overrides the available memory.
"""

from __future__ import annotations

import os

from mbplan.errors import InputError

_BASE_BYTES = 250e6  # interpreter, Pinocchio, CasADi, numba (251 MB extrapolated to N = 0)
_PER_KNOT_BYTES = {"maximal": 1.4e6 / 49, "generalized": 0.1e6 / 7}


def plan_memory_bytes(formulation: str, n_bodies: int, N: int) -> float:
    """Estimated peak memory (bytes) of planning ``N`` steps of an ``n_bodies`` arm;
    ``formulation``: ``"maximal"`` (RIPM) or ``"generalized"`` (IPOPT, Crocoddyl)."""
    scale = n_bodies**2 if formulation == "maximal" else n_bodies
    return _BASE_BYTES + _PER_KNOT_BYTES[formulation] * scale * (N + 1)


def available_memory_bytes() -> float:
    """``MBPLAN_MEMORY_LIMIT_GB`` if set, else the kernel's MemAvailable (inf if unknown)."""
    limit = os.environ.get("MBPLAN_MEMORY_LIMIT_GB")
    if limit:
        try:
            return float(limit) * 1e9
        except ValueError:
            raise InputError(f"MBPLAN_MEMORY_LIMIT_GB={limit!r} is not a number") from None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return float("inf")


def check_plan_memory(formulation: str, n_bodies: int, N: int, what: str = "horizon") -> None:
    """Raise :class:`InputError` with the estimate when planning would exceed the available
    memory."""
    need, have = plan_memory_bytes(formulation, n_bodies, N), available_memory_bytes()
    if need > have:
        raise InputError(
            f"{what} N={N}: planning {n_bodies} bodies in {formulation} coordinates needs about "
            f"{need / 1e9:.1f} GB (estimate), more than the {have / 1e9:.1f} GB available; "
            "reduce the horizon (or set MBPLAN_MEMORY_LIMIT_GB)"
        )
