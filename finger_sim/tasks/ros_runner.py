"""Run a task against a ROS 2 controller node: finger_node in lockstep, the node's MCAP log scored.

The runner starts, on the loopback interface and in the current ROS_DOMAIN_ID:
- finger_node on the task's scene (written to `<workdir>/scene.yaml`) with `lockstep:=true`,
  `command_qos:=reliable`, `realtime_factor:=0` and its log in a new `<workdir>/log_*/`;
- the controller executable (e.g. `finger_grip_controller`) with the task's first setpoint as its
  `setpoint` parameter, `sample_period` = the scene's dt, the given parameters, and two remaps:
  its `grip_force` comes from the runner (`RELAY_TOPIC`), its `/clock` from nowhere (it then
  advances its law by `sample_period` per sample, as the offline path does);
- itself (first, then finger_node, then the controller once the node's grip_force is matched
  with the runner: the node's first state waits for a controller), an rclpy node that relays grip_force sample k to the controller, and before it, at a
  setpoint change of the task, publishes the new setpoint on `grip_setpoint` and waits until the
  controller's reader acknowledged it, so that the controller has it before the sample it answers.

finger_node steps k+1 only when the answer to state k has come, so the run is repeatable bit for
bit. Timing: the answer to state k acts over the step k → k+1 (sample_steps 1, delay_steps 0,
whatever the task file says; `lockstep_task`). After the task's last step the runner stops both
nodes (SIGINT, then SIGKILL; also on any failure) and scores the log with `task_scores`.

What finger_node steps itself, from the scene it is given: the task's tip-force disturbances (the
scene's `input.tip_force` profile) and breakable objects (finger_sim.scene_changes, the offline
runner's rule); a crush is read back from the log's `~/crush_log`. A drive task runs with a
controller that commands `motor_voltage` (e.g. `finger_task_controller` around `grip_voltage`:
`controller_command`); its electrical energy is scored from the logged `motor/voltage` and
`motor/current`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT, MOTOR_VOLTAGE
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError, FingerSimError
from finger_sim.scene_yaml import dump_scene
from finger_sim.tasks.metrics import judge, task_scores
from finger_sim.grasp_objects import Crush
from finger_sim.scene import Scene
from finger_sim.tasks.runner import COLUMNS, DRIVE_COLUMNS, TaskRun
from finger_sim.tasks.schema import Task
from finger_sim.tip_force_profile import first_step, tip_force_switches

#: The topic on which the runner hands grip_force samples to the controller.
RELAY_TOPIC = f"task_runner/{GRIP_FORCE.topic}"
#: Where the controller's /clock goes (nothing publishes there: it counts samples instead).
NO_CLOCK_TOPIC = "task_runner/no_clock"
#: Wall seconds between a setpoint change and the sample that must see it, once the controller's
#: reader acknowledged the setpoint: a margin only. The order does not rest on it: an acknowledged
#: setpoint is waiting in the controller before the sample is sent, and the shipped controllers
#: serve a setpoint before a sample that waits beside it (their subscriptions' creation order).
SETPOINT_LEAD = 0.3
#: Wall seconds finger_node waits for an answer before stepping on (never, for a live controller).
LOCKSTEP_TIMEOUT = 60.0
#: Wall seconds: nodes to start and discover each other; the whole run per simulated second.
START_TIMEOUT = 60.0
WALL_PER_SIM_SECOND = 120.0
#: Wall seconds a node gets to exit on SIGINT before it is killed.
STOP_TIMEOUT = 15.0
#: finger_node's torque limit: the largest allowed, so that only the controller saturates.
NODE_MAX_TORQUE = 100.0
#: The depth of the runner's reliable subscriptions and publishers (never drops a sample).
DEPTH = 1000


def lockstep_task(task: Task) -> Task:
    """`task` with the lockstep timing: every step sampled, the answer acting over the next step."""
    return dataclasses.replace(task, sample_steps=1, delay_steps=0)


def controller_command(executable: str) -> list[str]:
    """The controller node's command: an executable (name or path), or for `module:callable` a
    Python task controller run as a node (finger_sim.ros.task_controller, this Python)."""
    if ":" in executable:
        return [sys.executable, "-m", "finger_sim.ros.task_controller"]
    return [find_executable(executable)]


def find_executable(name: str) -> str:
    """The controller executable: this Python's bin folder first, then PATH."""
    found = shutil.which(name, path=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    if found is None:
        raise ConfigError("--ros-controller", "an executable ROS 2 controller node (e.g. finger_grip_controller)", name)
    return found


def run_ros_task(task: Task, executable: str, workdir: Path, *, label: str = "",
                 params: Mapping[str, float] | None = None) -> TaskRun:
    """Run `task` against the controller node `executable` (name or path) with `params`; score it."""
    task = lockstep_task(task)
    scene = task.scene
    dt, n = scene.dt, scene.step_count
    workdir.mkdir(parents=True, exist_ok=True)
    scene_data = scene.to_dict()  # the input is the controller's: before its first command acts it is 0
    scene_data["input"]["torque" if scene.drive is None else "voltage"] = {"type": "constant", "value": 0.0}
    (workdir / "scene.yaml").write_text(dump_scene(scene_data), encoding="utf-8")
    log_dir = Path(tempfile.mkdtemp(prefix="log_", dir=workdir))  # a run of its own: an earlier run's log stays apart
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PYTHONUNBUFFERED": "1"}
    for key in ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER"):
        env.pop(key, None)
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")  # the runner's own participant
    node_cmd = [sys.executable, "-m", "finger_sim.ros.node", "--ros-args",
                *_params(scene=str(workdir / "scene.yaml"), lockstep=True, command_qos="reliable",
                         lockstep_timeout=LOCKSTEP_TIMEOUT, realtime_factor=0.0, marker_rate_hz=0.0,
                         physics_rate_hz=1.0 / dt, max_torque=NODE_MAX_TORQUE, command_timeout=0.0,
                         record_dir=str(log_dir))]
    own = {"controller": executable} if ":" in executable else {}
    controller_cmd = [*controller_command(executable), "--ros-args",
                      *_params(**{**own, "setpoint": task.setpoints[0][1], "sample_period": dt, **(params or {})}),
                      "-r", f"{GRIP_FORCE.topic}:={RELAY_TOPIC}", "-r", f"/clock:={NO_CLOCK_TOPIC}"]
    changes = {first_step(t, dt): v for t, v in task.setpoints[1:]}
    start = time.perf_counter()
    procs: list[tuple[subprocess.Popen, Path]] = []
    try:
        with _Relay(changes, n) as relay:
            # finger_node first, and the controller only once the runner sees the node's grip_force:
            # the node's first state waits for the controller, so the runner misses no sample
            for cmd, name in ((node_cmd, "finger_node"), (controller_cmd, "controller")):
                out = workdir / f"{name}.out"
                with out.open("wb") as sink:
                    procs.append((subprocess.Popen(cmd, env=env, stdout=sink, stderr=subprocess.STDOUT,
                                                   start_new_session=True), out))
                if name == "finger_node":
                    relay.wait_for_node(START_TIMEOUT, procs)
            relay.wait(START_TIMEOUT + WALL_PER_SIM_SECOND * n * dt, procs)
        for proc, out in procs:  # finger_node first: it closes its log
            _stop(proc)
        status = procs[-1][0].returncode
        if status != 0:
            raise FingerSimError(f"finger_node exited with status {status}; see {procs[-1][1]}")
    finally:
        for proc, _ in procs:
            _stop(proc)
    wall = time.perf_counter() - start
    samples, crushes = read_samples(log_dir, n, task.setpoints, scene)
    grid = tuple((first_step(t, dt) * dt, v) for t, v in task.setpoints)
    drive = {c: samples[c] for c in DRIVE_COLUMNS if c in samples}
    scores = task_scores(samples["t"], samples[GRIP_FORCE.name], grid, task.hold_after, bool(crushes), outputs=drive,
                         torque=(samples["command"], samples["theta1"]) if task.input == "torque" else None)
    return TaskRun(task.name, label, samples, crushes, scores, judge(scores, task.limits), grid, dict(task.limits), wall)


def read_samples(log_dir: Path, n: int, setpoints: tuple[tuple[float, float], ...],
                 scene: Scene) -> tuple[dict[str, np.ndarray], list[Crush]]:
    """The COLUMNS of states 0..n from finger_node's log (rosbags), and with a drive its
    DRIVE_COLUMNS, and the crushes of `~/crush_log`; FingerSimError if the node held a command for
    want of an answer (a 'lockstep_timeout' event of `~/command_log`): joint_states by stamp, the other topics by
    log time (sim time); command k is what acted over step k → k+1 (the mcp effort of state k+1,
    with a drive the motor voltage of state k+1); the tip force is the scene's profile at step k."""
    from rosbags.highlevel import AnyReader

    dt = scene.dt
    logs = sorted(log_dir.glob("*.mcap"))
    if len(logs) != 1:
        raise FingerSimError(f"expected one MCAP log in {log_dir}, found {len(logs)}")
    step_ns = round(dt * 1e9)
    states: dict[int, tuple[float, float, float]] = {}
    topics = {f"/{o.topic}": o.name for o in (GRIP_FORCE, MOTOR_VOLTAGE, MOTOR_CURRENT)}
    series: dict[str, dict[int, float]] = {name: {} for name in topics.values()}
    crushes: list[Crush] = []
    held = 0  # states finger_node stepped on without the controller's answer ('lockstep_timeout' events)
    with AnyReader(logs) as reader:
        wanted = [c for c in reader.connections
                  if c.topic in ("/joint_states", "/finger_node/crush_log", "/finger_node/command_log", *topics)]
        for conn, log_time, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/finger_node/command_log":
                held += any(kv.key == "event" and kv.value == "lockstep_timeout" for kv in msg.values)
            elif conn.topic == "/joint_states":
                k = (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec) // step_ns
                states[k] = (msg.position[0], msg.velocity[0], msg.effort[0])
            elif conn.topic == "/finger_node/crush_log":
                v = {kv.key: kv.value for kv in msg.values}
                step = int(v["step"])
                crushes.append(Crush(v["object"], float(v["t"]), step, float(v["force"]), float(v["break_force"])))
            else:
                series[topics[conn.topic]][log_time // step_ns] = msg.data
    if held:
        raise FingerSimError(f"finger_node stepped {held} time(s) on the last command: no answer came within "
                             f"lockstep_timeout ({LOCKSTEP_TIMEOUT:g} s), so the run is not the controller's; "
                             "see finger_node.out in the run's folder")
    drive = scene.drive is not None
    needed = [series[GRIP_FORCE.name], *((series[MOTOR_VOLTAGE.name], series[MOTOR_CURRENT.name]) if drive else ())]
    missing = [k for k in range(n + 1) if k not in states or any(k not in s for s in needed)]
    if missing:
        raise FingerSimError(f"the log {logs[0]} lacks the states of {len(missing)} steps (first: {missing[0]})")
    columns = COLUMNS + (DRIVE_COLUMNS if drive else ())
    rows = np.zeros((n + 1, len(columns)))
    set_steps = [(first_step(t, dt), v) for t, v in setpoints]
    switches = sorted(tip_force_switches(scene).items())
    for k in range(n + 1):
        theta, rate, _ = states[k]
        setpoint = [v for s, v in set_steps if s <= k][-1]
        tip = next((f for s, f in reversed(switches) if s <= k), scene.tip_force)
        after = min(k + 1, n)
        command = series[MOTOR_VOLTAGE.name][after] if drive else states[after][2]
        rows[k, :9] = (k * dt, series[GRIP_FORCE.name][k], setpoint, theta, rate, command, tip[0], tip[1],
                       sum(c.step <= k for c in crushes))
        if drive:
            rows[k, 9:] = (series[MOTOR_VOLTAGE.name][k], series[MOTOR_CURRENT.name][k])
    return {name: np.ascontiguousarray(rows[:, i]) for i, name in enumerate(columns)}, crushes


class _Relay:
    """The runner's rclpy node: relays grip_force k to the controller, a setpoint change first."""

    def __init__(self, changes: Mapping[int, float], last: int) -> None:
        import rclpy
        from rclpy.duration import Duration
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile
        from std_msgs.msg import Float64

        self._rclpy, self._float, self._duration = rclpy, Float64, Duration
        self._changes, self._last = changes, last
        self._count = 0
        self._done = threading.Event()
        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node("finger_task_runner", context=self._context)
        qos = QoSProfile(depth=DEPTH)
        self._relay = self._node.create_publisher(Float64, RELAY_TOPIC, qos)
        self._setpoint = self._node.create_publisher(Float64, "grip_setpoint", qos)
        self._force = self._node.create_subscription(Float64, GRIP_FORCE.topic, self._on_force, qos)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, daemon=True)

    def __enter__(self) -> _Relay:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._executor.shutdown()
        self._node.destroy_node()
        self._rclpy.try_shutdown(context=self._context)
        self._thread.join(STOP_TIMEOUT)

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:  # noqa: BLE001 - the executor stops when the context shuts down
            pass

    def _on_force(self, msg) -> None:
        k = self._count
        self._count += 1
        if k == 0:  # the controller's subscriptions must be matched before the first sample goes
            deadline = time.monotonic() + START_TIMEOUT
            while min(self._relay.get_subscription_count(), self._setpoint.get_subscription_count()) == 0:
                if time.monotonic() > deadline:
                    return  # wait() reports the stalled run
                time.sleep(0.01)
        if k in self._changes:  # the controller holds the setpoint (acknowledged) before the sample goes
            self._setpoint.publish(self._float(data=self._changes[k]))
            if not self._setpoint.wait_for_all_acked(self._duration(seconds=START_TIMEOUT)):
                return  # wait() reports the stalled run
            time.sleep(SETPOINT_LEAD)
        self._relay.publish(msg)
        if k >= self._last:
            self._done.set()

    def wait_for_node(self, timeout: float, procs: list[tuple[subprocess.Popen, Path]]) -> None:
        """Until the runner's grip_force subscription is matched with finger_node's publisher."""
        deadline = time.monotonic() + timeout
        while self._force.get_publisher_count() == 0:
            self._check(procs)
            if time.monotonic() > deadline:
                raise FingerSimError(f"finger_node's grip_force did not reach the task runner within {timeout:g} s")
            time.sleep(0.05)

    def _check(self, procs: list[tuple[subprocess.Popen, Path]]) -> None:
        for proc, out in procs:
            if proc.poll() is not None:
                raise FingerSimError(f"{out.stem} exited with status {proc.returncode} during the task; see {out}")

    def wait(self, timeout: float, procs: list[tuple[subprocess.Popen, Path]]) -> None:
        """Until state `last` was relayed; FingerSimError if a node exits or the time runs out."""
        deadline = time.monotonic() + timeout
        while not self._done.wait(0.1):
            self._check(procs)
            if time.monotonic() > deadline:
                raise FingerSimError(f"the ROS task run did not reach its last step within {timeout:g} s "
                                     f"({self._count} samples relayed)")


def _params(**values: object) -> list[str]:
    """`-p key:=value` arguments (booleans as true/false, numbers with every digit)."""
    out = []
    for key, value in values.items():
        text = ("true" if value else "false") if isinstance(value, bool) else (
            repr(float(value)) if isinstance(value, float) and math.isfinite(value) else str(value))
        out += ["-p", f"{key}:={text}"]
    return out


def _stop(proc: subprocess.Popen) -> None:
    """SIGINT to the process's group, SIGKILL after STOP_TIMEOUT; nothing if it has exited."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(STOP_TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        pass
