"""finger_pd_controller: its control law, and the closed loop with finger_node over DDS.

Reference for the loop: the static equilibrium of the PD law against the PIP spring on the
constraint manifold, kp·(θ* − θ) = kβ·dβ/dθ1 (spec §3, virtual work), solved with the core's
closed-form kinematics. PD settles there, 5 mrad short of θ* = 0.8 rad with the defaults.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from scipy.optimize import brentq

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from finger_sim import kinematics  # noqa: E402
from finger_sim.ros import conversions  # noqa: E402
from finger_sim.ros.pd_controller import KD, KP, MAX_TORQUE, pd_torque  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402

PAPER = Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml"
SETPOINT = 0.8  # rad
#: The stated performance (spec finger, default gains, realtime_factor 1, loop delay of a few ms):
SETTLE_S = 0.5  # sim s after the first torque ...
TOL_EQ = 2e-3  # rad: ... θ1 stays this close to the PD/spring equilibrium ...
TOL_SETPOINT = 0.01  # rad: ... and this close to the setpoint,
OVERSHOOT = 0.03  # rad: never beyond the setpoint by more than this,
WINDOW_S = 1.0  # sim s: checked up to here.


def equilibrium(setpoint: float, kp: float) -> float:
    """θ1 where kp (θ* − θ1) = kβ dβ/dθ1, rad: the PD's rest point against the PIP spring."""
    scene = load_scene(PAPER)
    p, k = scene.params, scene.spring_stiffness
    alpha = kinematics.distal_offset(p)

    def residual(t1: float) -> float:
        q = kinematics.assemble(p, t1)
        rates = kinematics.dependent_rates(p, q, 1.0)  # dq/dθ1
        return kp * (setpoint - t1) - k * kinematics.pip_angle(q, alpha) * (rates[2] - rates[0])

    return brentq(residual, 0.0, 1.2, xtol=1e-14)


def test_pd_law():
    assert pd_torque(0.8, 0.7, 0.0, 0.2, 0.01, 0.05) == pytest.approx(0.2 * 0.1)
    assert pd_torque(0.8, 0.8, 2.0, 0.2, 0.01, 0.05) == pytest.approx(-0.02)  # damping on the rate
    assert pd_torque(0.8, 0.0, 0.0, 0.2, 0.01, 0.05) == 0.05  # saturated
    assert pd_torque(-0.8, 0.0, 0.0, 0.2, 0.01, 0.05) == -0.05
    assert pd_torque(0.3, 0.3, 0.0, 0.2, 0.01, 0.05) == 0.0


def test_equilibrium_is_short_of_the_setpoint_by_the_spring():
    eq = equilibrium(SETPOINT, KP)
    assert SETPOINT - 0.01 < eq < SETPOINT  # the spring holds it back, by a few mrad


def test_pd_brings_the_mcp_to_the_setpoint(launcher, ros_client):
    launcher.node("finger_sim.ros.node", dict(scene=str(PAPER), realtime_factor=1.0, command_timeout=0.5), name="finger_node")
    launcher.node("finger_sim.ros.pd_controller", dict(setpoint=0.0), name="pd")
    states = ros_client.collect(JointState, "/joint_states")
    setpoint_pub = ros_client.publisher(Float64, "/mcp_setpoint")
    ros_client.wait_for(lambda: setpoint_pub.get_subscription_count(), "the controller's setpoint subscription")
    ros_client.wait_for(lambda: states, "the node's states")  # from here on we see every state
    assert all(m.effort[0] == 0.0 for m in states)  # at rest, setpoint 0

    def started():
        setpoint_pub.publish(Float64(data=SETPOINT))  # repeated until the finger moves
        return next((m for m in states if m.effort[0] > 0.0), None)

    first = ros_client.wait_for(started, "the controller's first torque")
    t0 = conversions.from_time(first.header.stamp) * 1e-9
    assert first.effort[0] == MAX_TORQUE  # kp·0.8 = 0.16 N·m saturates
    ros_client.wait_for(lambda: conversions.from_time(states[-1].header.stamp) * 1e-9 >= t0 + WINDOW_S,
                        f"{WINDOW_S} s of closed loop", timeout=30.0)

    eq = equilibrium(SETPOINT, KP)
    run = [(conversions.from_time(m.header.stamp) * 1e-9 - t0, m.position[0]) for m in states]
    run = [(t, th) for t, th in run if 0.0 <= t <= WINDOW_S]
    settled = [th for t, th in run if t >= SETTLE_S]
    assert len(settled) > 100
    assert max(abs(th - eq) for th in settled) < TOL_EQ
    assert max(abs(th - SETPOINT) for th in settled) < TOL_SETPOINT
    assert max(th for _, th in run) < SETPOINT + OVERSHOOT
    assert math.isclose(KD, 0.01) and math.isclose(KP, 0.2)  # the gains these bounds are stated for
