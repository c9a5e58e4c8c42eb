"""The residual protocol: a residual kind is one class that owns every translation of itself.

A residual is plain data (its targets, frames, limits); :meth:`Residual.resolve` checks it against
the robot and scene and fills in every default. Costs are ``½ w ‖r‖²``; constraints are ``r = 0``
(``sense = "eq"``) or ``r ≤ 0`` (``"ineq"``). State residuals live on the knots ``k = 1..N``,
control residuals on the intervals ``k = 0..N-1``.

Each formulation iterates over an OCP's items and asks their residuals for its translation,
passing a context it provides (symbolic kinematics, the maximal layout, the Crocoddyl state):

* joint space (:meth:`Residual.joint_space`): :class:`SymbolicRows`, a CasADi expression of the
  knot's ``x = (q, v)`` or ``x = τ`` (generalized coordinates, the verifier, Crocoddyl's
  fallback), or rows with their own derivatives in ``q`` (coal distances);
  :meth:`Residual.variable_bounds` makes a constraint a bound on the decision variables;
* maximal coordinates (:meth:`Residual.maximal_terms`): RIPM terms on the bodies' poses;
* a free body (:meth:`Residual.body_rows`): one CasADi expression of ``(R, p, F, v)`` or ``u``;
* shooting (:meth:`Residual.shooting`): a Crocoddyl residual model, its bounds, its FDDP penalty;
* verification: :attr:`Residual.is_obstacle` (checked by :meth:`Residual.clearance` on the replay),
  :meth:`Residual.violation_tolerance` and :meth:`Residual.violation_reason`.

An obstacle residual with :attr:`Residual.between_knots` also holds along each interval's motion:
the generalized formulation adds its joint-space rows at configurations of the interval
(:mod:`mbplan.formulations.interval_rows`), the maximal formulation terms on the bodies'
interpolated poses (its :meth:`Residual.maximal_terms`); shooting and free bodies refuse it.

A translation a kind does not provide raises :class:`~mbplan.errors.InputError` naming the
residual and the formulation (:meth:`Residual.inexpressible`), before any solve. Every subclass
whose name does not start with ``_`` is registered in :data:`RESIDUALS` (``kind`` of its
:meth:`Residual.to_dict`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.validation import as_array

if TYPE_CHECKING:
    import casadi as cs

    from mbplan.ocp.problem import Item
    from mbplan.ocp.scene import Scene

TORQUE_TOLERANCE = 1e-6  # relative to max(1, limit): torques on the applied torques
CONSTRAINT_TOLERANCE = 1e-4  # residual units (m, rad, rad/s, N m): IPOPT's default constr_viol_tol

RESIDUALS: dict[str, type[Residual]] = {}
"""Every residual kind by class name (filled as the classes are defined)."""


@dataclass(frozen=True)
class SymbolicContext:
    """What a joint-space residual's CasADi rows read: the ``robot``, the knot variable ``x``
    (``(q, v)`` for state residuals, ``τ`` for control ones), the parameters ``theta`` and the
    joints' world placements ``(R, p)`` at the symbolic ``q`` (``placements()``, built on demand)."""

    robot: Any
    x: cs.SX
    theta: cs.SX
    placements: Callable[[], list[tuple[cs.SX, cs.SX]]]

    @property
    def q(self) -> cs.SX:
        """The joint positions by velocity index (``nv``; a floating base's six are zero: the
        base has frame residuals, not joint ones)."""
        robot = self.robot
        if robot.nq == robot.nv:
            return self.x[: robot.nv]
        joint = robot.q_of_v >= 0
        return self.x[np.where(joint, robot.q_of_v, 0).tolist()] * joint.astype(float)

    @property
    def v(self) -> cs.SX:
        return self.x[self.robot.nq :]


@dataclass(frozen=True, eq=False)
class SymbolicRows:
    """A joint-space residual as CasADi rows ``r(x, θ)``: ``rows(ctx)`` builds them from a
    :class:`SymbolicContext`. Rows of equal ``key`` (and number of parameters) are equal, so
    residuals of one structure on one robot share one function, whatever their ``parameters``
    ``θ``."""

    key: Hashable
    parameters: np.ndarray
    rows: Callable[[SymbolicContext], cs.SX]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SymbolicRows) and self._identity() == other._identity()

    def __hash__(self) -> int:
        return hash(self._identity())

    def _identity(self) -> tuple:
        return self.key, self.parameters.size


@dataclass(frozen=True)
class ShootingResidual:
    """A residual in Crocoddyl: its ``model`` (a ``ResidualModelAbstract``), constraint bounds
    ``lower ≤ r ≤ upper``, the FDDP penalty ``weight`` (None: the node's control bounds impose
    it), and for a cost the weights of a weighted quadratic ``activation`` (None: ``½‖r‖²``)."""

    model: Any
    lower: np.ndarray
    upper: np.ndarray
    weight: float | None
    activation: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Residual:
    """Base class of the residual kinds (module docstring). ``space`` is ``"state"`` or
    ``"control"``, ``sense`` the constraint sense, ``cost``/``constraint`` whether it can be a
    cost / a constraint, ``free_body`` whether it applies to a free body, ``is_obstacle`` whether it
    keeps the robot out of an obstacle (the verifier checks it on the replay's substeps),
    ``between_knots`` whether its rows also hold between the knots (module docstring)."""

    space: ClassVar[str] = "state"
    sense: ClassVar[str] = "eq"
    cost: ClassVar[bool] = True
    constraint: ClassVar[bool] = True
    free_body: ClassVar[bool] = False
    is_obstacle: ClassVar[bool] = False
    # not annotated: obstacle residuals redefine it as their last field
    between_knots = False
    input_limits: ClassVar[bool] = False  # limits the applied torques or inputs
    steps: ClassVar[bool] = False  # reads a free body's rotation step F (evaluating it needs dt)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not cls.__name__.startswith("_"):
            RESIDUALS[cls.__name__] = cls

    # -- problem data --------------------------------------------------------------------------
    def resolve(self, robot: Any, scene: Scene) -> Residual:
        """This residual checked against ``robot`` and ``scene``, every default filled in."""
        return self

    def dim(self, robot: Any, scene: Scene) -> int:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": type(self).__name__}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out

    @staticmethod
    def from_dict(data: dict[str, Any]) -> Residual:
        kind = data.get("kind")
        cls = RESIDUALS.get(kind)  # type: ignore[arg-type]
        if cls is None:
            raise InputError(f"unknown residual kind {kind!r}; known: {sorted(RESIDUALS)}")
        kwargs = {k: v for k, v in data.items() if k != "kind"}
        if "between_knots" in {f.name for f in fields(cls)}:  # no key: a knot-only constraint
            kwargs.setdefault("between_knots", False)
        for k, v in kwargs.items():
            if isinstance(v, list):
                kwargs[k] = tuple(v) if k in ("joints", "objects") else np.array(v, dtype=float)
        return cls(**kwargs)

    def inexpressible(self, formulation: str) -> InputError:
        """The error of a translation this kind does not provide."""
        return InputError(f"{type(self).__name__} cannot be expressed in {formulation}")

    def between_knots_form(self) -> Residual:
        """The residual whose joint-space rows a formulation evaluates between knots."""
        return self

    def knots_only(self, formulation: str) -> None:
        """Raise :class:`InputError` if this residual holds between knots, which
        ``formulation`` cannot express."""
        if self.between_knots:
            raise InputError(
                f"{type(self).__name__}(between_knots=True) cannot be expressed in "
                f"{formulation}, which constrains the knots only; pass between_knots=False"
            )

    # -- joint space (generalized coordinates, the verifier) -----------------------------------
    def joint_space(self, robot: Any, scene: Scene) -> Any:
        """:class:`SymbolicRows`, or rows with their own derivatives in ``q`` (``size``,
        ``values(q)``, ``jacobian(q)``, ``jacobian_support()``, ``hessian(q, μ)``; see
        :class:`mbplan.residuals.distance.DistanceRows`)."""
        raise self.inexpressible("joint coordinates")

    def variable_bounds(self, robot: Any) -> tuple[str, np.ndarray, np.ndarray] | None:
        """``(variable, lower, upper)`` if this constraint is a bound on ``q``, ``v``, ``tau``
        (a robot) or ``u`` (a free body), else None."""
        return None

    def row_label(self, robot: Any, scene: Scene, row: int) -> str:
        """What row ``row`` measures (for messages)."""
        return f"row {row}"

    def start_violation(self, robot: Any, scene: Scene, row: int, value: float) -> str:
        """How the start violates row ``row`` by ``value`` (for messages)."""
        return f"{self.row_label(robot, scene, row)} by {value:.4g}"

    # -- maximal coordinates and the free body -------------------------------------------------
    def maximal_terms(self, ctx: Any, item: Item) -> list:
        """The RIPM :class:`~mbplan.transcription.terms.Term` list of ``item`` on SO(3)×R³
        bodies; ``ctx`` is the :class:`~mbplan.formulations.maximal.MaximalNLP`."""
        raise self.inexpressible("maximal coordinates")

    def body_parameters(self, scene: Scene) -> dict[str, Any]:
        """The numbers :meth:`body_rows` reads (targets, limits, a cylinder)."""
        raise self.inexpressible("a free body's coordinates")

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        """The residual at a free body's state ``x = {R, p, F, v}`` or input ``x = {u}`` with
        parameters ``P`` (:meth:`body_parameters`), CasADi symbols or numbers."""
        raise InputError(f"{cls.__name__} cannot be expressed in a free body's coordinates")

    # -- shooting ------------------------------------------------------------------------------
    def shooting(self, ctx: Any, item: Item) -> ShootingResidual:
        """The Crocoddyl residual of ``item``; ``ctx`` is the
        :class:`~mbplan.formulations.crocoddyl.ShootingBuilder` (default: the joint-space rows
        as a Python residual, :meth:`~mbplan.formulations.crocoddyl.ShootingBuilder.symbolic`)."""
        return ctx.symbolic(item)

    # -- verification --------------------------------------------------------------------------
    def clearance(
        self, robot: Any, scene: Scene, path: np.ndarray, evaluate: Callable | None
    ) -> float:
        """Smallest clearance (m, without the margin) of an :attr:`is_obstacle` residual along
        ``path`` ``(K, nq)``; ``evaluate(residual, q)`` gives this residual's rows there (None for
        a free body's positions)."""
        raise self.inexpressible("an obstacle clearance")

    def violation_tolerance(self, tolerance: float | None) -> float:
        """The largest violation at the planned knots that passes (``tolerance``: the item's)."""
        return CONSTRAINT_TOLERANCE if tolerance is None else tolerance

    def violation_reason(self, name: str, violation: float, tolerance: float) -> str:
        return (
            f"constraint {name!r} is violated by {violation:.3g} at the planned knots "
            f"(tolerance {tolerance:g})"
        )


def vector(value: ArrayLike | None, n: int, name: str, default: float = 0.0) -> np.ndarray:
    """``value`` as an ``(n,)`` array (``default`` everywhere if None)."""
    return np.full(n, default) if value is None else as_array(value, (n,), name)
