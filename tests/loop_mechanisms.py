"""Mechanisms with loop closures for the tests: a planar four-bar (MJCF, crank actuated) and
spatial serial chains closed to the world."""

from __future__ import annotations

import tempfile
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin

from mbplan.robots import Robot, load_robot
from mbplan.robots.loops import Loop

FOURBAR_MJCF = """<mujoco model="fourbar">
  <worldbody>
    <body name="base" pos="0 0 0">
      <body name="crank" pos="0 0 0">
        <joint name="crank_joint" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01" mass="0.1"/>
        <body name="coupler" pos="0.1 0 0">
          <joint name="coupler_joint" type="hinge" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.01" mass="0.2"/>
          <site name="coupler_tip" pos="0 0 0.3"/>
        </body>
      </body>
      <body name="rocker" pos="0.3 0 0">
        <joint name="rocker_joint" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 -0.2 0 0.3" size="0.01" mass="0.2"/>
      </body>
    </body>
  </worldbody>
  <equality>
    <connect name="close" body1="coupler" body2="rocker" anchor="0 0 0.3"/>
  </equality>
  <actuator><motor joint="crank_joint"/></actuator>
</mujoco>
"""


@cache
def fourbar_path() -> Path:
    """The four-bar's MJCF file (written once per test process)."""
    path = Path(tempfile.mkdtemp(prefix="mbplan-fourbar-")) / "fourbar.xml"
    path.write_text(FOURBAR_MJCF)
    return path


def fourbar() -> Robot:
    """The planar four-bar: crank (actuated), coupler and rocker (passive), a point closure
    between coupler and rocker (its out-of-plane row redundant)."""
    return load_robot(fourbar_path())


# joint axes of the spatial chain (unit vectors in the joint frames), link offsets
AXES = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 0))
OFFSETS = (
    (0.0, 0.0, 0.1),
    (0.15, 0.0, 0.05),
    (0.0, 0.15, 0.05),
    (0.12, 0.02, 0.0),
    (0.0, 0.1, 0.06),
    (0.08, 0.0, 0.08),
    (0.05, 0.07, 0.0),
)
TIP = np.array([0.1, 0.04, 0.03])  # the closing point on the last link


def spatial_chain(kind: str = "point", joints: int = 4) -> Robot:
    """A serial chain of ``joints`` revolute joints with skew axes (:data:`AXES`), its last link
    closed to the world by a ``kind`` closure that holds at neutral; the first joint actuated:
    an RRRRS linkage with the defaults (one degree of freedom)."""
    return spatial_branches(((kind, joints),))


def spatial_branches(branches: tuple[tuple[str, int], ...]) -> Robot:
    """One :func:`spatial_chain` per ``(kind, joints)`` of ``branches``, each from the world
    (joints ``b{i}j{k}``, each branch's first one actuated; loops ``tip{i}``)."""
    model = pin.Model()
    model.name = "spatial_" + "_".join(f"{k}{n}" for k, n in branches)
    data, loops = None, []
    for b, (kind, joints) in enumerate(branches):
        parent = 0
        for i in range(joints):
            rotation = pin.exp3(0.3 * np.array(AXES[(i + 1) % 7], float))
            placement = pin.SE3(rotation, np.array(OFFSETS[i]) + 0.3 * b * (i == 0))
            axis = pin.JointModelRevoluteUnaligned(np.array(AXES[i % 7], float))
            jid = model.addJoint(parent, axis, placement, f"b{b}j{i}")
            model.lowerPositionLimit[jid - 1], model.upperPositionLimit[jid - 1] = -3.0, 3.0
            lever = np.array([0.04, 0.02, 0.03]) * (1 + 0.2 * i)
            inertia = pin.Inertia(0.5 + 0.1 * i, lever, np.diag([2e-3, 3e-3, 4e-3]))
            model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
            parent = jid
        data = model.createData()
        pin.forwardKinematics(model, data, pin.neutral(model))
        tip = pin.SE3(pin.exp3(np.array([0.2, -0.1, 0.3])), TIP)
        world = data.oMi[parent] * tip
        loops.append(
            Loop(
                f"tip{b}",
                kind,
                f"b{b}j{joints - 1}",
                tip.homogeneous,
                "universe",
                world.homogeneous,
            )
        )
    actuated = [f"b{b}j0" for b in range(len(branches))]
    return load_robot(model, loops=loops, actuated=actuated)
