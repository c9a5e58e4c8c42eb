"""Colours of a replay: a tint per formulation (maximal blue-ish, generalized orange-ish, a
different shade for each further result of the same formulation), the goal and the obstacles."""

from __future__ import annotations

from collections.abc import Sequence

from mbplan.errors import InputError
from mbplan.results import PlanResult
from mbplan.viz.shapes import Rgba

COLORS = ("formulation", "materials")  # what a robot copy is drawn in
MAXIMAL_TINTS = ((0.2, 0.45, 0.9), (0.45, 0.3, 0.85), (0.1, 0.6, 0.7))
GENERALIZED_TINTS = ((0.95, 0.5, 0.1), (0.9, 0.75, 0.1), (0.75, 0.4, 0.25))
GOAL_RGBA: Rgba = (0.2, 0.8, 0.3, 0.3)
OBSTACLE_RGBA: Rgba = (0.85, 0.2, 0.2, 0.35)


def formulation_tints(results: Sequence[PlanResult]) -> list[tuple[float, float, float]]:
    """One colour per result: the k-th maximal result (it carries ``R``) the k-th of
    :data:`MAXIMAL_TINTS`, the k-th generalized one the k-th of :data:`GENERALIZED_TINTS`."""
    seen = {True: 0, False: 0}
    out = []
    for result in results:
        maximal = result.R is not None
        palette = MAXIMAL_TINTS if maximal else GENERALIZED_TINTS
        out.append(palette[seen[maximal] % len(palette)])
        seen[maximal] += 1
    return out


def check_colors(colors: str) -> str:
    """``colors`` if it is one of :data:`COLORS`, else :class:`InputError`."""
    if colors not in COLORS:
        raise InputError(f"colors: expected one of {', '.join(COLORS)}, got {colors!r}")
    return colors
