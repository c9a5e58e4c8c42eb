"""Matplotlib figures of planning results: convergence, KKT/Hessian sparsity, joint trajectories.

Every function draws on its own :class:`matplotlib.figure.Figure` (no pyplot state, no GUI
backend), writes ``path`` atomically (format from the suffix: ``.png``, ``.svg`` or ``.pdf``) and
returns it.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from matplotlib.figure import Figure

from mbplan.errors import InputError
from mbplan.results import PlanResult

_FORMATS = (".png", ".svg", ".pdf")


def result_label(result: PlanResult) -> str:
    """``"<method> (maximal)"`` or ``"<method> (generalized)"``: maximal solutions carry ``R``."""
    return f"{result.method} ({'generalized' if result.R is None else 'maximal'})"


def write_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and
    :func:`os.replace`, creating the folder; return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def plot_convergence(
    results: Sequence[PlanResult],
    path: str | os.PathLike[str],
    labels: Sequence[str] | None = None,
) -> Path:
    """KKT error ``max(inf_pr, inf_du)`` (log scale) against the iteration, one line per result
    (from :attr:`PlanResult.kkt_history`); returns ``path``."""
    labels = _labels(results, labels)
    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    for result, label in zip(results, labels, strict=True):
        history = result.kkt_history
        if len(history) == 0:
            raise InputError(f"plot_convergence: {label} has an empty kkt_history")
        ax.semilogy(np.arange(len(history)), np.max(history, axis=1), label=label)
    ax.set_xlabel("iteration")
    ax.set_ylabel("KKT error max(primal, dual infeasibility)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return _save(fig, path)


def plot_sparsity(
    matrices: Mapping[str, sp.spmatrix | sp.sparray], path: str | os.PathLike[str]
) -> Path:
    """Sparsity patterns side by side (like the RIPM paper's Fig. 7), e.g.
    ``{"KKT matrix": K, "Hessian": H}``, each titled with its shape and non-zero count;
    returns ``path``."""
    if not matrices:
        raise InputError("plot_sparsity: no matrices given")
    fig = Figure(figsize=(4.2 * len(matrices), 4.4), layout="constrained")
    axes = fig.subplots(1, len(matrices), squeeze=False)[0]
    for ax, (name, matrix) in zip(axes, matrices.items(), strict=True):
        if not sp.issparse(matrix):
            raise InputError(f"plot_sparsity: {name!r} is a {type(matrix).__name__}, not sparse")
        coo = sp.coo_matrix(matrix)
        coo.eliminate_zeros()
        rows, cols = coo.shape
        marker = min(2.0, max(0.05, 300.0 / max(rows, cols)))
        ax.spy(coo, markersize=marker, color="k")
        ax.set_title(f"{name}\n{rows}×{cols}, {coo.nnz} non-zeros", fontsize=10)
        ax.tick_params(labelsize=8)
    return _save(fig, path)


def plot_trajectories(
    results: Sequence[PlanResult],
    path: str | os.PathLike[str],
    labels: Sequence[str] | None = None,
    joint_names: Sequence[str] | None = None,
) -> Path:
    """Joint positions (left column) and torques (right column, held over each step) against
    time, one row per joint and one line per result; returns ``path``."""
    labels = _labels(results, labels)
    nq, nv = results[0].q.shape[1], results[0].tau.shape[1]
    for result, label in zip(results, labels, strict=True):
        if result.q.shape[1] != nq or result.tau.shape[1] != nv:
            raise InputError(
                f"plot_trajectories: {label} has {result.q.shape[1]} positions and "
                f"{result.tau.shape[1]} torques, the first result {nq} and {nv}"
            )
    if nq != nv:
        raise InputError(f"plot_trajectories: needs nq = nv (1-dof joints), got {nq} and {nv}")
    names = [f"joint {j + 1}" for j in range(nq)] if joint_names is None else list(joint_names)
    if len(names) != nq:
        raise InputError(f"plot_trajectories: {len(names)} joint names for {nq} joints")
    fig = Figure(figsize=(10.0, 1.6 * nq + 0.8), layout="constrained")
    axes = fig.subplots(nq, 2, sharex=True, squeeze=False)
    for result, label in zip(results, labels, strict=True):
        t = result.dt * np.arange(len(result.q))
        for j in range(nq):
            (line,) = axes[j, 0].plot(t, result.q[:, j], label=label)
            tau = np.append(result.tau[:, j], result.tau[-1, j])
            axes[j, 1].step(t, tau, where="post", color=line.get_color())
    for j, name in enumerate(names):
        axes[j, 0].set_ylabel(f"{name}\nq [rad]", fontsize=8)
        axes[j, 1].set_ylabel("τ [N m]", fontsize=8)
        for ax in axes[j]:
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[0, 0].set_title("joint positions")
    axes[0, 1].set_title("joint torques")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncols=4)
    return _save(fig, path)


def _labels(results: Sequence[PlanResult], labels: Sequence[str] | None) -> list[str]:
    if not results:
        raise InputError("no results to plot")
    for i, result in enumerate(results):
        if not isinstance(result, PlanResult):
            raise InputError(f"results[{i}]: expected a PlanResult, got {type(result).__name__}")
    if labels is None:
        return [result_label(r) for r in results]
    if len(labels) != len(results):
        raise InputError(f"{len(labels)} labels for {len(results)} results")
    return [str(label) for label in labels]


def _save(fig: Figure, path: str | os.PathLike[str]) -> Path:
    path = Path(path)
    if path.suffix.lower() not in _FORMATS:
        raise InputError(f"{path}: the file name must end in one of {', '.join(_FORMATS)}")
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lower()[1:], dpi=120, bbox_inches="tight")
    return write_atomic(path, buf.getvalue())
