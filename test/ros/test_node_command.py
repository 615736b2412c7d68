"""`finger-sim node ...` against a running finger_node (issue 19, item 10), as a user runs it: the
console script in its own process (`echo`, `pub`, the no-node error; the other calls go through the
same main() in this process). Also: an int for a float parameter (item 11), exact clock
values in service answers (item 11), and /clock while paused (item 9, through `echo`).

References: an offline Simulator of the same scene at the node's rate fed the same torque
(joint states bit for bit), the 500 Hz step grid (clock values), and the node's read-only flags.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy")

from finger_sim import joints, kinematics  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.scene_paths import resolve_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from helpers import run_cli_here  # noqa: E402

NODE = "finger_sim.ros.node"
FINGER_SIM = Path(sys.executable).with_name("finger-sim")
RATE = 500  # given as an int: physics_rate_hz:=500
STEPS_PER_TRIGGER = 10
PUBLISH_HZ = 50.0  # a state every 10 steps: one for each ~/step call
TORQUE = 0.01  # N·m
TIMEOUT_S = 60.0
DRIVE_GRASP = Path(__file__).resolve().parents[2] / "config" / "drive_grasp.yaml"


def node_cli(launcher, *args: object, timeout: float = 20.0) -> subprocess.CompletedProcess:
    """`finger-sim node ARGS` in its own process, as a user runs it."""
    return subprocess.run([str(FINGER_SIM), "node", "--timeout", str(timeout), *map(str, args)], env=launcher.env,
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False)


def node_here(*args: object, timeout: float = 20.0) -> subprocess.CompletedProcess:
    """The same command through finger_sim.cli.main in this process (the ros_domain fixture has set
    this process's ROS environment): a process start-up less per call. The process boundary stays
    tested by node_cli and the `echo` and `pub` processes."""
    return run_cli_here("node", "--timeout", timeout, *args)


def ok(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stdout + done.stderr
    return done.stdout


def one_line_error(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stdout + done.stderr
    (line,) = done.stderr.splitlines()
    assert line.startswith("finger-sim node: error: "), line
    return line


def test_the_node_command_drives_a_running_node(launcher, ros_client):
    launcher.node(NODE, dict(start_paused=True, steps_per_trigger=STEPS_PER_TRIGGER, publish_rate_hz=PUBLISH_HZ,
                             record=False),
                  ros_args=["-p", f"physics_rate_hz:={RATE}"])
    assert ok(node_here("get", "physics_rate_hz")) == "physics_rate_hz = 500.0\n"  # the int, as a float
    assert "motor torque 0.01 N·m sent to /motor_torque" in ok(node_here("torque", TORQUE))

    echo = subprocess.Popen([str(FINGER_SIM), "node", "echo", "/joint_states", "-n", "3"], env=launcher.env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    answers: list[str] = []

    def echoed() -> bool:
        """One more ~/step call (10 steps of 2 ms, one state) until echo has its three states and exits:
        the node's publisher may match echo's subscription after the graph shows it (discovery
        completes on each side apart), and a state sent before that does not reach echo."""
        if echo.poll() is not None:
            return True
        answers.append(ok(node_here("step")).strip())
        return False

    try:
        ros_client.wait_for(lambda: ros_client.node.count_subscribers("/joint_states") >= 1, "echo's subscription",
                            TIMEOUT_S)  # a process start: 20 s was not enough at load ~21
        ros_client.wait_for(echoed, "echo's three states", TIMEOUT_S)
        out, err = echo.communicate(timeout=TIMEOUT_S)
    finally:
        echo.kill()
    assert echo.returncode == 0, err
    assert answers[0] == "clock=0.02 time=0.02 step=10 episode=0", answers
    assert [a.split()[2] for a in answers] == [f"step={10 * (k + 1)}" for k in range(len(answers))]
    documents = [yaml.safe_load(d) for d in out.split("---\n") if d.strip()]
    stamps = [d["header"]["stamp"]["sec"] * 10**9 + d["header"]["stamp"]["nanosec"] for d in documents]
    assert len(stamps) == 3 and stamps[0] % 20_000_000 == 0 and 0 < stamps[0] <= len(answers) * 20_000_000
    assert stamps == [stamps[0], stamps[0] + 20_000_000, stamps[0] + 40_000_000]  # consecutive states, one per call
    state = documents[-1]

    sim = Simulator(load_scene(resolve_scene("finger_default")).with_overrides(dt=1.0 / RATE))
    for _ in range(stamps[-1] // 2_000_000):
        sim.step(TORQUE)
    p = sim.scene.params
    assert state["name"] == list(joints.JOINT_NAMES)
    assert state["position"] == list(joints.joint_positions(sim.q, kinematics.extended_pose(p), kinematics.distal_offset(p)))
    assert state["velocity"] == list(joints.joint_velocities(sim.v))
    assert state["effort"][0] == TORQUE

    clock = yaml.safe_load(ok(node_here("echo", "/clock", "-n", "1")).split("---")[0])
    assert clock == {"clock": dict(zip(("sec", "nanosec"), divmod(len(answers) * 20_000_000, 10**9)))}  # republished while paused

    assert ok(node_here("set", "realtime_factor", "2")) == "realtime_factor = 2.0\n"
    refused = one_line_error(node_here("set", "physics_rate_hz", "100.0"))
    assert "refused physics_rate_hz = 100.0" in refused and "read-only" in refused
    assert ok(node_here("resume")).startswith("running; clock=")
    assert ok(node_here("pause")).startswith("paused; clock=")
    reset = ok(node_here("reset"))
    assert reset.endswith("time=0.0 step=0 episode=1\n"), reset
    assert "no parameter 'no_such'" in one_line_error(node_here("get", "no_such"))


def test_no_node_is_one_line_naming_the_service(launcher):
    line = one_line_error(node_cli(launcher, "--node", "/nobody", "reset", timeout=1.0))
    assert "no service /nobody/reset within 1 s" in line and "ROS_DOMAIN_ID=" in line


def test_pub_delivers_one_float(launcher, ros_client):
    """`node pub` (for the README's grip setpoint): one Float64, to a reliable and a best-effort subscriber."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    reliable = ros_client.collect(Float64, "/grip_setpoint")
    best_effort = ros_client.collect(Float64, "/grip_setpoint", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    done = subprocess.Popen([str(FINGER_SIM), "node", "pub", "/grip_setpoint", "0.5"], env=launcher.env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ros_client.wait_for(lambda: (reliable and best_effort) or done.poll() is not None, "the setpoint at both subscribers")
        out, err = done.communicate(timeout=TIMEOUT_S)
    finally:
        done.kill()
    assert done.returncode == 0, err
    ros_client.wait_for(lambda: reliable and best_effort, "the setpoint at both subscribers")
    assert out == "published 0.5 on /grip_setpoint (2 subscribers)\n"
    assert [m.data for m in reliable] == [m.data for m in best_effort] == [0.5]


def test_voltage_drives_a_node_with_a_drive(launcher, ros_client):
    """`finger-sim node voltage 3` on drive_grasp (spec §8): the node holds 3 V from the step it
    takes effect; its joint states equal an offline Simulator of the scene fed 3 V from there."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from finger_sim.ros import conversions

    rate, volts, steps = 1000.0, 3.0, 3 * STEPS_PER_TRIGGER
    launcher.node(NODE, dict(scene=str(DRIVE_GRASP), start_paused=True, steps_per_trigger=STEPS_PER_TRIGGER,
                             command_timeout=0.0, physics_rate_hz=rate, record=False))
    states = ros_client.collect(JointState, "/joint_states")
    voltages = ros_client.collect(Float64, "/motor/voltage")
    assert "motor voltage 3.0 V sent to /motor_voltage" in ok(node_here("voltage", volts))
    answer = ok(node_here("step", 3))
    assert answer.strip() == "clock=0.03 time=0.03 step=30 episode=0", answer
    ros_client.wait_for(lambda: any(conversions.from_time(m.header.stamp) == 30_000_000 for m in states),
                        "the state at step 30")
    (last,) = [m for m in states if conversions.from_time(m.header.stamp) == 30_000_000]

    sim = Simulator(load_scene(DRIVE_GRASP).with_overrides(dt=1.0 / rate))
    for _ in range(steps):
        sim.step(volts)  # paused at step 0: the voltage holds from the first step
    p = sim.scene.params
    assert last.position.tolist() == list(joints.joint_positions(sim.q, kinematics.extended_pose(p), kinematics.distal_offset(p)))
    assert last.effort[0] == sim.system.motor_outputs(sim.time, sim.q, sim.v, sim.torque)["mesh_torque"]
    assert voltages and voltages[-1].data == volts
    assert last.position[0] > 0.0  # the motor did turn the finger
