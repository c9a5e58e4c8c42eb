"""Visualisation of planning results: MeshCat replays (:mod:`mbplan.viz.meshcat_replay`) and
matplotlib figures (:mod:`mbplan.viz.plots`)."""

from mbplan.viz.meshcat_replay import (
    MeshcatServer,
    draw_drone,
    draw_results,
    drone_replay,
    generalized_geometry_placements,
    infer_robot,
    maximal_geometry_placements,
    read_result,
    replay,
    replay_main,
    serve,
    static_html,
)
from mbplan.viz.plots import plot_convergence, plot_sparsity, plot_trajectories, result_label

__all__ = [
    "MeshcatServer",
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
