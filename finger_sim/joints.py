"""Joint-space conventions of spec §6, both ways: paper angles q ↔ (mcp, coupler, pip).

Positions are zero at extension and positive in flexion: mcp = θ1 − θ1_ext,
coupler = θ2 − θ2_ext, pip = β = θ3 + α − θ1. Velocities are their rates.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from finger_sim import kinematics
from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem

JOINT_NAMES = ("mcp_joint", "coupler_joint", "pip_joint")
#: dθ3 = dβ = 1: a pure PIP rotation, the direction along which the PIP spring's k is read.
PIP_ROTATION: Vec3 = (0.0, 0.0, 1.0)


def joint_positions(q: Vec3, q_ext: Vec3, alpha: float) -> Vec3:
    """(mcp, coupler, pip) positions, rad, from q = (θ1, θ2, θ3)."""
    return (q[0] - q_ext[0], q[1] - q_ext[1], q[2] + alpha - q[0])


def joint_velocities(v: Vec3) -> Vec3:
    """(mcp, coupler, pip) rates, rad/s, from q'."""
    return (v[0], v[1], v[2] - v[0])


def paper_coordinates(positions: Vec3, velocities: Vec3, q_ext: Vec3, alpha: float) -> tuple[Vec3, Vec3]:
    """(q, q') from joint positions and rates: the inverse of the two functions above."""
    t1 = positions[0] + q_ext[0]
    return (
        (t1, positions[1] + q_ext[1], positions[2] + t1 - alpha),
        (velocities[0], velocities[1], velocities[2] + velocities[0]),
    )


def pip_stiffness(system: FingerSystem) -> float:
    """The PIP spring's k, N·m/rad, through the force-element protocol: the stiffness the smooth
    elements put on a pure PIP rotation at extension (the pip_joint effort is −kβ). Non-smooth
    ones are left out: a contact reports a design stiffness even out of contact, for the
    stability check."""
    q_ext = kinematics.extended_pose(system.params)
    return sum(e.modal(q_ext, PIP_ROTATION)[0] for e in system.elements if e.smooth)
