"""Benchmark tasks of the RIPM paper (§VIII) as plain data, with samplers and simulators.

The package exports the drone docking task (:mod:`mbplan.tasks.drone`, whose ``__all__`` lists
the names); the iiwa obstacle task is an :class:`mbplan.OCP` of :mod:`mbplan.paper`.
"""

from mbplan.tasks import drone
from mbplan.tasks.drone import *  # noqa: F403  (the names of drone.__all__)

__all__ = drone.__all__
