"""The tight hybrid reference itself (test/hybrid_reference.py), on what the event tests lean on it for.

A finger at rest on a stop leaves it where the free acceleration stops pushing into it, wherever that
falls inside a smooth piece of the input (not only at the piece's end, where the push may be back).
The independent checks: the sign of the load (a negative torque and the spring both pull the finger
off the upper stop, so no state can rest there then), and finger_sim's own stepping, which locates
the same release within each 1 ms step.
"""

from __future__ import annotations

import math

import numpy as np

import hybrid_reference as hybrid
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate

UPPER = math.pi / 2  # rad, the upper MCP stop
#: τ = OFFSET + AMPLITUDE sin(2π F t), N·m: presses the finger onto the upper stop, then pulls (τ < 0)
#: for about 0.07 s of each period, and presses again before the piece (the whole run) ends.
OFFSET, AMPLITUDE, F = 0.003, 0.004, 2.0
SCENE = {"model": {"spring_stiffness": 0.001, "joint_limits": {"mcp": [0.0, UPPER]}, "restitution": 0.0},
         "input": {"torque": {"type": "sine", "offset": OFFSET, "amplitude": AMPLITUDE, "frequency": F}},
         "initial": {"theta1": 1.4, "theta1_dot": 0.0}, "duration": 0.6,
         "integrator": {"method": "auto", "dt": 0.001}}
#: θ1 of auto against the reference over the run, rad (auto's promise is 1e-6; measured 1.2e-9).
THETA_TOLERANCE = 1e-6


def test_a_release_from_the_stop_inside_one_long_piece_is_located():
    """The finger reaches the upper stop at ≈ 0.1 s and rests; the sine input turns negative at ≈ 0.30 s
    and is positive again at the run's end, so only a release located inside the piece lets it go.
    Where τ < 0 (and later) the finger is off the stop; θ1 follows finger_sim's stepping throughout."""
    reference = hybrid.solve(SCENE)
    traj = simulate(scene_from_dict(SCENE))
    theta = reference.states(traj.t)[0]
    assert (theta[traj.t < 0.09] < UPPER).all() and (theta == UPPER).any()  # it does reach and rest on the stop
    pulled = OFFSET + AMPLITUDE * np.sin(2 * math.pi * F * traj.t) < 0.0
    assert pulled.any() and (theta[pulled] < UPPER - 1e-3).all()
    assert np.abs(theta - traj.q[:, 0]).max() < THETA_TOLERANCE
