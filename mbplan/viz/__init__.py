"""Visualisation of planning results: MeshCat replays (:mod:`mbplan.viz.replay`, the drone's
:mod:`mbplan.viz.drone`; static pages :mod:`mbplan.viz.page`, the live server
:mod:`mbplan.viz.server`) and matplotlib figures (:mod:`mbplan.viz.plots`)."""

from mbplan.viz.camera import bounding_box, camera_offset
from mbplan.viz.drone import draw_drone, drone_replay
from mbplan.viz.placements import generalized_geometry_placements, maximal_geometry_placements
from mbplan.viz.plots import plot_convergence, plot_sparsity, plot_trajectories, result_label
from mbplan.viz.replay import (
    draw_results,
    infer_robot,
    read_result,
    replay,
    replay_main,
    serve,
    static_html,
)
from mbplan.viz.server import MeshcatServer

__all__ = [
    "MeshcatServer",
    "bounding_box",
    "camera_offset",
    "draw_drone",
    "draw_results",
    "drone_replay",
    "generalized_geometry_placements",
    "infer_robot",
    "maximal_geometry_placements",
    "plot_convergence",
    "plot_sparsity",
    "plot_trajectories",
    "read_result",
    "replay",
    "replay_main",
    "result_label",
    "serve",
    "static_html",
]
