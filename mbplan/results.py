"""The outcome of a trajectory optimization, common to all methods, and its ``.npz`` file format."""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.errors import InputError, MbplanError
from mbplan.solvers.result import SolverResult
from mbplan.validation import output_file

_ARRAYS = (
    "q", "v", "tau", "kkt_history", "R", "p", "tau_knots", "contact_forces",
    "contact_forces_knots",
)  # fmt: skip
_OPTIONAL = (
    "R", "p", "body_names", "tau_knots", "formulation", "violations", "goal_errors",
    "contact_forces", "contact_forces_knots", "contact_frames",
)  # fmt: skip
_JSON = ("extra", "violations", "goal_errors")


@dataclass(frozen=True, eq=False)
class PlanResult(SolverResult):
    """A planned trajectory and solver statistics (like ``scipy.optimize.OptimizeResult``).

    ``q (N+1, nq)``, ``v (N+1, nv)`` at the knots, ``tau (N, nv)`` held over ``[t_k, t_{k+1}]``,
    ``dt`` (s). ``status`` is the solver's status string, ``success`` its convergence flag; a
    result with non-finite ``q``, ``v`` or ``tau`` is never successful. ``solve_time_s`` is the
    solver's wall time (including callbacks), ``total_time_s`` the plan's (building the problem,
    warm start, compilation, solve), ``time_per_iter_s = solve_time_s / max(iterations, 1)``;
    ``compile_time_s`` is the part of ``total_time_s`` spent building, compiling and loading
    kernels (CasADi functions compiled to C, numba functions: :mod:`mbplan.engine.compile_clock`;
    large on a first run only, as the compiled kernels are cached on disk), which neither
    ``solve_time_s`` nor ``extra["build_time_s"]`` include. ``kkt_history (iterations+1, 2)``
    holds the primal and dual infeasibility ``(inf_pr, inf_du)`` per iteration, iteration 0 first.
    ``entered_restoration`` is None when the solver has no restoration phase. Maximal-coordinate
    solutions add body orientations ``R (N+1, nb, 3, 3)``, COM positions ``p (N+1, nb, 3)`` and
    ``body_names``. A method whose forces act at the knots (the LGVI) adds the knot torques
    ``tau_knots (N+1, nv)``: the torque then ramps linearly from ``tau_knots[k]`` to
    ``tau_knots[k+1]`` over ``[t_k, t_{k+1}]`` (first-order hold) and ``tau`` must be its interval
    mean. A plan with contacts (:meth:`mbplan.OCP.add_contact`) adds ``contact_frames`` and
    ``contact_forces (N, nc, 3)``: each contact's world force (N) on the robot at its frame,
    the mean over each interval (force × Δt is its impulse; zero where it does not act), and
    the LGVI's knot forces ``contact_forces_knots (N+1, nc, 3)`` (the verifier applies them,
    with ``tau_knots``, as impulses at the knots; ``v`` is then the velocity midway through each
    knot's impulse, :func:`mbplan.formulations.maximal.impulse_midpoint_velocities`);
    ``(…, 6)`` when a contact is a sole: the world force, then the world torque (N m) about the
    frame's origin (a point's zero).
    ``extra`` holds method-specific numbers (JSON-serialisable).

    One meaning of ``success`` for every method (:func:`mbplan.plan`): the solver converged to
    its tolerance, the trajectory is finite, and every hard constraint of the OCP holds at the
    planned knots (``violations``: largest violation per constraint name). ``goal_errors``: the
    error of each soft goal (a cost with a tolerance) at its last knot. ``ocp`` is the problem
    the plan solves (saved in the ``.npz``), ``formulation`` ``"maximal"``/``"generalized"``/…
    """

    method: str
    status: str
    success: bool
    message: str
    iterations: int
    solve_time_s: float
    total_time_s: float
    time_per_iter_s: float
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    dt: float
    compile_time_s: float = 0.0
    kkt_history: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    entered_restoration: bool | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    R: np.ndarray | None = None
    p: np.ndarray | None = None
    body_names: tuple[str, ...] | None = None
    tau_knots: np.ndarray | None = None
    contact_forces: np.ndarray | None = None
    contact_forces_knots: np.ndarray | None = None
    contact_frames: tuple[str, ...] | None = None
    formulation: str | None = None
    violations: dict[str, float] | None = None
    goal_errors: dict[str, float] | None = None
    ocp: Any = None

    def __post_init__(self) -> None:
        for name in _ARRAYS:
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, np.asarray(value, dtype=float))
        q, v, tau = self.q, self.v, self.tau
        if (
            q.ndim != 2
            or v.ndim != 2
            or tau.ndim != 2
            or len(q) != len(v)
            or len(tau) != len(q) - 1
        ):
            raise InputError(
                f"PlanResult: expected q (N+1, nq), v (N+1, nv), tau (N, nv); got "
                f"{q.shape}, {v.shape}, {tau.shape}"
            )
        if self.kkt_history.ndim != 2 or self.kkt_history.shape[1] != 2:
            raise InputError(
                f"PlanResult.kkt_history: expected (n, 2), got {self.kkt_history.shape}"
            )
        knots = self.tau_knots
        if knots is not None:
            if knots.shape != (len(q), tau.shape[1]):
                raise InputError(
                    f"PlanResult.tau_knots: expected {(len(q), tau.shape[1])}, got {knots.shape}"
                )
            mean = 0.5 * (knots[:-1] + knots[1:])
            if not np.allclose(tau, mean, rtol=1e-12, atol=1e-12, equal_nan=True):
                raise InputError("PlanResult: tau is not the interval mean of tau_knots")
        finite = all(np.all(np.isfinite(a)) for a in (q, v, tau))
        if self.success and not finite:
            raise InputError("PlanResult: success=True with non-finite q, v or tau")
        for name in ("body_names", "contact_frames"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, tuple(str(n) for n in getattr(self, name)))
        self._check_contacts()

    def _check_contacts(self) -> None:
        forces, knots, frames = self.contact_forces, self.contact_forces_knots, self.contact_frames
        if forces is None:
            if knots is not None or frames:
                raise InputError("PlanResult: contact_forces_knots or frames without forces")
            return
        shape = (len(self.tau), len(frames or ()), forces.shape[-1] if forces.ndim == 3 else 3)
        if forces.shape != shape or shape[-1] not in (3, 6):
            raise InputError(f"PlanResult.contact_forces: expected {shape}, got {forces.shape}")
        if knots is not None:
            if knots.shape != (shape[0] + 1, *shape[1:]):
                raise InputError(
                    f"PlanResult.contact_forces_knots: expected {(shape[0] + 1, *shape[1:])}, "
                    f"got {knots.shape}"
                )
            if not np.allclose(forces, 0.5 * (knots[:-1] + knots[1:]), rtol=1e-12, atol=1e-12):
                raise InputError(
                    "PlanResult: contact_forces is not the interval mean of contact_forces_knots"
                )

    @property
    def objective(self) -> float:
        """The solver's objective at the plan (``extra["objective"]``; NaN if not reported)."""
        return float(self.extra.get("objective", float("nan")))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """:func:`save_npz` of this result (with its OCP); returns the path written."""
        return save_npz(self, path)


def save_npz(result: PlanResult, path: str | os.PathLike[str]) -> Path:
    """Write ``result`` to ``path`` (``.npz``) atomically: a temporary file in the same folder,
    then :func:`os.replace`. Every field is stored (``extra`` as JSON; None fields are left out);
    returns the path written."""
    path = output_file(path, (".npz",), "save_npz")
    if not isinstance(result, PlanResult):
        raise InputError(f"save_npz: expected a PlanResult, got {type(result).__name__}")
    arrays: dict[str, np.ndarray] = {}
    for f in fields(PlanResult):
        value = getattr(result, f.name)
        if value is None:
            continue
        if f.name == "ocp":
            arrays["ocp"] = np.asarray(json.dumps(value.to_dict()))
            continue
        if f.name in _JSON:
            try:
                value = json.dumps(value, default=_to_json)
            except (TypeError, ValueError) as err:
                raise InputError(
                    f"save_npz: PlanResult.extra is not JSON-serialisable: {err}"
                ) from None
        arrays[f.name] = np.asarray(value)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except OSError as err:  # a full disk, a folder removed meanwhile, ...
        raise InputError(f"save_npz: cannot write {path}: {err.strerror or err}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load_npz(path: str | os.PathLike[str], robot: Any = None) -> PlanResult:
    """Read a :class:`PlanResult` written by :func:`save_npz`, with its OCP when the file has
    one (files from before the OCP API have none: ``ocp`` is then None). The OCP's robot is
    loaded from its source, or is ``robot`` (needed when it was an in-memory model).
    :class:`InputError` naming the file if it is missing, not a ``.npz`` (zip) archive, a
    truncated or damaged one, or holds no such result. Object arrays are never unpickled."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"load_npz: {path}: no such result file")
    not_result = f"load_npz: {path} is not a PlanResult .npz file"
    if not zipfile.is_zipfile(path):
        raise InputError(f"{not_result}: not a zip archive (another kind of file, or truncated)")
    try:
        return _load(path, robot)
    except MbplanError as err:
        raise InputError(f"load_npz: {path}: {err}") from None
    except (OSError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise InputError(f"{not_result}: damaged archive ({type(err).__name__})") from None


def _load(path: Path, robot: Any) -> PlanResult:
    with np.load(path, allow_pickle=False) as data:
        data_keys = set(data.files)
        missing = [f.name for f in fields(PlanResult) if f.name not in data and _required(f.name)]
        if missing:
            raise InputError(f"not a PlanResult .npz file: it lacks the fields {missing}")
        kwargs: dict[str, Any] = {}
        for f in fields(PlanResult):
            if f.name in data:
                try:
                    kwargs[f.name] = _field(f.name, data[f.name])
                except (ValueError, TypeError):  # object arrays, bad JSON, wrong kinds
                    raise InputError(
                        f"not a PlanResult .npz file: its field {f.name!r} is not what "
                        "save_npz writes"
                    ) from None
    if "ocp" in data_keys:
        kwargs["ocp"], unavailable = _load_ocp(kwargs["ocp"], robot, path)
        if kwargs["ocp"] is None:
            kwargs["extra"] = {**kwargs.get("extra", {}), "ocp_unavailable": unavailable}
    return PlanResult(**kwargs)


def _field(name: str, value: np.ndarray) -> Any:
    """The :class:`PlanResult` field ``name`` from its stored array (the OCP as its JSON text)."""
    if name in _JSON:
        return json.loads(str(value))
    if name == "ocp":
        return str(value)
    if name in ("body_names", "contact_frames"):
        return tuple(str(n) for n in value)
    if name in _ARRAYS:
        return np.array(value, dtype=float)
    return value.item()


def _load_ocp(text: str, robot: Any, path: Any) -> tuple[Any, str]:
    """The saved OCP, or None and why not (e.g. its robot was an in-memory model)."""
    from mbplan.ocp.problem import OCP

    try:
        return OCP.from_dict(json.loads(text), robot), ""
    except MbplanError as err:
        return None, f"{path}: cannot rebuild the plan's OCP: {err}"
    except (ValueError, KeyError, TypeError):
        return None, f"{path}: cannot rebuild the plan's OCP: its saved description is malformed"


def _required(name: str) -> bool:
    return name not in _OPTIONAL and name not in (
        "compile_time_s",
        "kkt_history",
        "entered_restoration",
        "extra",
        "ocp",
    )


def _to_json(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")
