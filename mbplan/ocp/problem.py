"""The optimal control problem, described once for every formulation.

An :class:`OCP` holds a robot (a fixed-base :class:`~mbplan.robots.robot.Robot` or a
:class:`~mbplan.robots.free_body.FreeBody`, whose ``q0, v0`` follow Pinocchio's free flyer), a scene, a horizon of ``N`` steps of ``dt`` from the initial state
``(q0, v0)`` (knot 0, fixed), and named costs and constraints built from
:mod:`mbplan.residuals`. Knots: ``"all"`` (state knots ``1..N``, intervals ``0..N-1``),
``"running"`` (state knots ``1..N-1``, intervals ``0..N-1``), ``"terminal"`` (knot ``N``) or a
list of indices. A cost is ``weight · ½‖r‖²`` summed over its knots; ``tolerance`` marks a soft
goal whose error :func:`mbplan.verify` checks at the last knot. A constraint's ``tolerance``
replaces the verifier's default acceptance of its violation at the planned knots. Each mimic
coupling of the robot (:class:`~mbplan.robots.robot.Mimic`) is a
:class:`~mbplan.residuals.coupling.JointCoupling` constraint ``mimic_<follower>`` on every state
knot, added by the constructor; ``q0`` must satisfy it. The robot's passive joints get a
:class:`~mbplan.residuals.joint.JointTorque` constraint ``passive`` (zero torque on every
interval) and no other torque goal; ``q0`` must close the robot's loops
(:mod:`mbplan.robots.loops`), whose constraints and forces are part of every formulation's
dynamics. Contacts (:meth:`OCP.add_contact`, :mod:`mbplan.ocp.contacts`) hold robot frames at
ground points over stances, their forces variables of the dynamics with hard friction cones.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mbplan.errors import InputError
from mbplan.ocp.contacts import Contact, contact_from_dict, make_contact
from mbplan.ocp.scene import Scene
from mbplan.residuals.base import RESIDUALS, Residual
from mbplan.residuals.coupling import JointCoupling
from mbplan.residuals.joint import JointTorque
from mbplan.robots.free_body import FreeBody
from mbplan.robots.loops import close_loops, closure_residual
from mbplan.robots.robot import Mimic, Robot, load_robot, robot_from_source
from mbplan.validation import as_array, as_int, as_real

Knots = str | Sequence[int]
MIMIC_START_TOLERANCE = 1e-9  # rad or m: how far q0 may be off a mimic coupling
LOOP_START_TOLERANCE = 1e-8  # m or rad: how far q0 may be off a loop closure


@dataclass(frozen=True, eq=False)
class Item:
    """A named cost (``weight``) or constraint on ``knots`` (state knots or intervals)."""

    name: str
    role: str  # "cost" | "constraint"
    residual: Residual
    knots: np.ndarray
    weight: float = 0.0
    tolerance: float | None = None

    @property
    def sense(self) -> str:
        return "cost" if self.role == "cost" else self.residual.sense


class OCP:
    """A trajectory optimization problem; ``add_cost``/``add_constraint`` return the OCP.

    ``robot``: anything :func:`mbplan.robots.robot.load_robot` takes. ``q0`` defaults to the
    robot's ``default`` reference configuration (SRDF) or neutral; ``v0`` to zero.
    """

    def __init__(
        self,
        robot: Any,
        scene: Scene | None = None,
        *,
        N: int = 40,
        dt: float = 0.075,
        q0: ArrayLike | None = None,
        v0: ArrayLike | None = None,
    ) -> None:
        self.robot: Robot | FreeBody = load_robot(robot)
        if scene is not None and not isinstance(scene, Scene):
            raise InputError(f"scene: expected a Scene, got {type(scene).__name__}")
        self.scene = scene if scene is not None else Scene()
        self.N = as_int(N, "N", minimum=2, what="horizon")
        self.dt = as_real(dt, "dt", positive=True)
        nq, nv = self.robot.nq, self.robot.nv
        if isinstance(self.robot, FreeBody):
            q0 = np.r_[np.zeros(6), 1.0] if q0 is None else q0
        elif q0 is None:
            refs = self.robot.model.referenceConfigurations
            q0 = self.robot.configuration("default" if "default" in refs else "neutral")
        self.q0 = as_array(q0, (nq,), "q0")
        if isinstance(self.robot, FreeBody) or getattr(self.robot, "floating", False):
            quat = self.q0[3:7]
            if abs(np.linalg.norm(quat) - 1.0) > 1e-9:
                raise InputError(f"q0: quaternion {quat} (x, y, z, w) is not of unit norm")
            if quat[3] < 0.0:  # the plans' sign: w ≥ 0
                self.q0 = np.r_[self.q0[:3], -quat, self.q0[7:]]
        self.v0 = as_array(np.zeros(nv) if v0 is None else v0, (nv,), "v0")
        self.items: list[Item] = []
        self.contacts: list[Contact] = []
        for c in getattr(self.robot, "mimic", ()):
            self._couple(c)
        self._check_loops()
        passive = getattr(self.robot, "passive", ())
        if passive:
            self.add_constraint("passive", JointTorque(joints=passive))

    # -- building ------------------------------------------------------------------------------
    def add_cost(
        self,
        name: str,
        residual: Residual,
        weight: float = 1.0,
        knots: Knots = "all",
        tolerance: float | None = None,
    ) -> OCP:
        if not isinstance(residual, Residual):
            raise InputError(f"cost {name!r}: expected a residual, got {type(residual).__name__}")
        if not residual.cost:
            raise InputError(f"cost {name!r}: {type(residual).__name__} can only be a constraint")
        w = as_real(weight, f"cost {name!r} weight", positive=True)
        tol = None if tolerance is None else as_real(tolerance, f"cost {name!r} tolerance")
        return self._add(Item(name, "cost", residual, self._knots(name, residual, knots), w, tol))

    def add_constraint(
        self, name: str, residual: Residual, knots: Knots = "all", tolerance: float | None = None
    ) -> OCP:
        if not isinstance(residual, Residual):
            raise InputError(
                f"constraint {name!r}: expected a residual, got {type(residual).__name__}"
            )
        if not residual.constraint:
            raise InputError(f"constraint {name!r}: {type(residual).__name__} can only be a cost")
        tol = None if tolerance is None else as_real(tolerance, f"constraint {name!r} tolerance")
        knots_ = self._knots(name, residual, knots)
        return self._add(Item(name, "constraint", residual, knots_, tolerance=tol))

    def add_contact(
        self,
        name: str,
        frame: str,
        knots: Sequence[int],
        position: ArrayLike | None = None,
        friction: float = 0.7,
        sole: tuple[float, float] | None = None,
    ) -> OCP:
        """Hold ``frame`` at the ground point ``position`` (default: where ``q0`` puts it) over
        the stance ``knots`` (contiguous state knots), its force inside the friction cone of
        coefficient ``friction``; with ``sole = (length, width)`` a flat rectangular sole held
        in place and orientation, its wrench inside the contact wrench cone
        (:mod:`mbplan.ocp.contacts`)."""
        if not isinstance(name, str) or not name:
            raise InputError(f"name: expected a non-empty string, got {name!r}")
        if name in self.names or name in self.contact_names:
            raise InputError(f"the OCP already has a cost, constraint or contact named {name!r}")
        if isinstance(self.robot, FreeBody):
            raise InputError(f"contact {name!r}: a free body has no frames to hold")
        if self.robot.loops:
            raise InputError(
                f"contact {name!r}: contacts are not written for a robot with loop closures"
            )
        contact = make_contact(
            self.robot,
            self.N,
            self.q0,
            self.v0,
            self.dt,
            name,
            frame,
            knots,
            position,
            friction,
            sole,
        )
        for other in self.contacts:
            both = np.intersect1d(other.knots, contact.knots)
            if other.frame == contact.frame and both.size:
                raise InputError(
                    f"contact {name!r}: frame {frame!r} is already held by contact "
                    f"{other.name!r} at knots {both.tolist()}"
                )
        self.contacts.append(contact)
        return self

    @property
    def contact_names(self) -> list[str]:
        return [c.name for c in self.contacts]

    @property
    def contact_frames(self) -> list[str]:
        """The frames of the contacts, in order."""
        return [c.frame for c in self.contacts]

    def add_terminal_cost(self, name: str, residual: Residual, weight: float = 1.0, **kw) -> OCP:
        return self.add_cost(name, residual, weight, knots="terminal", **kw)

    def add_terminal_constraint(self, name: str, residual: Residual) -> OCP:
        return self.add_constraint(name, residual, knots="terminal")

    def _couple(self, c: Mimic) -> None:
        """The constraint of mimic coupling ``c`` on every state knot (q0 must satisfy it)."""
        follow = int(self.robot.q_of_v[self.robot.joint_indices([c.follower])[0]])
        expected = self.robot.coupled(self.q0)[follow]
        if abs(self.q0[follow] - expected) > MIMIC_START_TOLERANCE:
            raise InputError(
                f"q0: joint {c.follower!r} is at {self.q0[follow]:.6g}, but it mimics "
                f"{c.leader!r}, which puts it at {expected:.6g}; set it there, or load the robot "
                "with mimic='independent'"
            )
        residual = JointCoupling(c.follower, c.leader, c.multiplier, c.offset)
        self.add_constraint(f"mimic_{c.follower}", residual)

    def _check_loops(self) -> None:
        """``q0`` closes every loop of the robot (else: the residual and where it would close)."""
        loops = getattr(self.robot, "loops", ())
        if not loops:
            return
        model = self.robot.model
        gap = np.abs(closure_residual(model, loops, self.q0))
        if gap.max() > LOOP_START_TOLERANCE:
            actuated = np.setdiff1d(
                np.arange(self.robot.nv), self.robot.joint_indices(self.robot.passive)
            )
            closed, left = close_loops(model, loops, self.q0, fixed=actuated)
            if left > LOOP_START_TOLERANCE:  # the actuated joints cannot stay: move them too
                closed, left = close_loops(model, loops, self.q0)
            where = (
                f"it would close at q0 = {np.array2string(closed, precision=6, separator=', ')}"
                if left <= LOOP_START_TOLERANCE
                else "no configuration near it closes them"
            )
            names = ", ".join(loop.name for loop in loops)
            raise InputError(
                f"q0 does not close the loops ({names}): residual {gap.max():.3g}; {where} "
                "(mbplan.robots.loops.close_loops)"
            )

    def _add(self, item: Item) -> OCP:
        if not isinstance(item.name, str) or not item.name:
            raise InputError(f"name: expected a non-empty string, got {item.name!r}")
        if item.name in self.names or item.name in self.contact_names:
            raise InputError(
                f"the OCP already has a cost, constraint or contact named {item.name!r}"
            )
        if isinstance(self.robot, FreeBody) and not item.residual.free_body:
            kinds = [name for name, cls in RESIDUALS.items() if cls.free_body]
            raise InputError(
                f"{item.role} {item.name!r}: {type(item.residual).__name__} is not a residual "
                f"of a free body; use {kinds}"
            )
        passive = set(getattr(self.robot, "passive", ())) & set(
            getattr(item.residual, "joints", None) or ()
        )
        if passive and isinstance(item.residual, JointTorque) and item.name != "passive":
            raise InputError(
                f"{item.role} {item.name!r}: joints {sorted(passive)} are passive (no actuator): "
                "their torque is zero and takes no goal"
            )
        try:
            resolved = item.residual.resolve(self.robot, self.scene)
        except InputError as err:
            raise InputError(f"{item.role} {item.name!r}: {err}") from None
        self.items.append(
            Item(item.name, item.role, resolved, item.knots, item.weight, item.tolerance)
        )
        return self

    def _knots(self, name: str, residual: Residual, knots: Knots) -> np.ndarray:
        control = residual.space == "control"
        N = self.N
        if isinstance(knots, str):
            table = {
                "all": np.arange(N) if control else np.arange(1, N + 1),
                "running": np.arange(N) if control else np.arange(1, N),
                "terminal": None if control else np.array([N]),
            }
            if knots not in table:
                raise InputError(f"{name!r}: knots must be all, running, terminal or a list")
            if table[knots] is None:
                raise InputError(f"{name!r}: torques live on the intervals 0..N-1, not at knot N")
            return table[knots]
        k = np.unique(np.asarray(knots, dtype=np.int64).ravel())
        lo, hi = (0, N - 1) if control else (1, N)
        if k.size == 0 or k[0] < lo or k[-1] > hi:
            raise InputError(f"{name!r}: knots {list(knots)} outside {lo}..{hi}")
        return k

    # -- queries -------------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        return [i.name for i in self.items]

    def __getitem__(self, name: str) -> Item:
        for i in self.items:
            if i.name == name:
                return i
        raise InputError(f"the OCP has no cost or constraint {name!r}; it has {self.names}")

    @property
    def costs(self) -> list[Item]:
        return [i for i in self.items if i.role == "cost"]

    @property
    def constraints(self) -> list[Item]:
        return [i for i in self.items if i.role == "constraint"]

    def __repr__(self) -> str:
        parts = ", ".join(
            [f"{i.role} {i.name}" for i in self.items]
            + [f"contact {n}" for n in self.contact_names]
        )
        return (
            f"OCP({self.robot.name}, N={self.N}, dt={self.dt:g}, scene={self.scene.names}, {parts})"
        )

    # -- serialisation -------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "robot": self.robot.source,
            "scene": self.scene.to_dict(),
            "N": self.N,
            "dt": self.dt,
            "q0": self.q0.tolist(),
            "v0": self.v0.tolist(),
            "items": [
                {
                    "name": i.name,
                    "role": i.role,
                    "residual": i.residual.to_dict(),
                    "knots": i.knots.tolist(),
                    "weight": i.weight,
                    "tolerance": i.tolerance,
                }
                for i in self.items
            ],
            "contacts": [c.to_dict() for c in self.contacts],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], robot: Any = None) -> OCP:
        """Rebuild an OCP saved by :meth:`to_dict` (the robot is loaded from its source unless
        given)."""
        robot = robot_from_source(data["robot"]) if robot is None else robot
        ocp = cls(
            robot,
            Scene.from_dict(data["scene"]),
            N=int(data["N"]),
            dt=float(data["dt"]),
            q0=data["q0"],
            v0=data["v0"],
        )
        # the robot's couplings and passive joints, as a saved file holds them
        implied = {i.name: json.loads(json.dumps(i.residual.to_dict())) for i in ocp.items}
        for d in data["items"]:
            if implied.get(d["name"]) == json.loads(json.dumps(d["residual"])):
                continue
            residual = Residual.from_dict(d["residual"])
            if d["role"] == "cost":
                ocp.add_cost(d["name"], residual, d["weight"], d["knots"], d.get("tolerance"))
            else:
                ocp.add_constraint(d["name"], residual, d["knots"], d.get("tolerance"))
        for d in data.get("contacts", ()):
            ocp.add_contact(**contact_from_dict(d))
        return ocp
