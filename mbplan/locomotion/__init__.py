"""Locomotion problems as data: gaits (schedules of contacts, swing targets) as OCPs."""

from mbplan.locomotion.gaits import (
    BIPED_GAITS,
    QUADRUPED_GAITS,
    Phase,
    biped_gait,
    biped_schedule,
    quadruped_gait,
    quadruped_schedule,
)

__all__ = [
    "BIPED_GAITS",
    "QUADRUPED_GAITS",
    "Phase",
    "biped_gait",
    "biped_schedule",
    "quadruped_gait",
    "quadruped_schedule",
]
