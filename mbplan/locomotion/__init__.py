"""Locomotion problems as data: gaits (schedules of contacts, swing targets) as OCPs."""

from mbplan.locomotion.gaits import QUADRUPED_GAITS, Phase, quadruped_gait, quadruped_schedule

__all__ = ["QUADRUPED_GAITS", "Phase", "quadruped_gait", "quadruped_schedule"]
