"""Offline tools over a node's MCAP log: info, export, resim. No ROS needed.

The node writes a metadata record `finger_sim` (see `run_metadata`) that holds the fully
resolved scene as it ran, so the log alone is enough to rebuild the run. The command log
(`<node>/command_log`, DiagnosticStatus key-values) says from which step of which episode
each torque was applied; re-applying them through the same `Simulator` reproduces the
recorded states bit for bit on the same version and platform.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from finger_sim import __version__, kinematics
from finger_sim.joints import JOINT_NAMES, joint_positions, joint_velocities, paper_coordinates
from finger_sim.log.errors import LogFileError
from finger_sim.log.reader import FINGER_SIM_METADATA, LogReader
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator, Trajectory

NS_PER_S = 1_000_000_000
Vec6 = tuple[float, float, float, float, float, float]  # joint positions (rad) + rates (rad/s)
#: Metadata keys the node writes and resim needs.
REQUIRED_KEYS = ("scene", "torque_source")


def run_metadata(scene: Scene, *, method: str, method_reason: str, torque_source: str, parameters: Mapping[str, Any]) -> dict[str, str]:
    """The `finger_sim` metadata record of a run: strings only, as MCAP metadata wants."""
    return {
        "version": __version__,
        "scene": scene.to_yaml(),
        "method": method,
        "method_reason": method_reason,
        "torque_source": torque_source,
        "dt": repr(scene.dt),
        "parameters": yaml.safe_dump(dict(parameters), sort_keys=True),
    }


@dataclass
class RecordedRun:
    """What a log says about one node run: its scene, commands and recorded states."""

    scene: Scene
    metadata: dict[str, str]
    torque_source: str
    joint_states: list[tuple[int, Vec6]] = field(default_factory=list)  # (stamp ns, positions + velocities)
    events: list[dict[str, str]] = field(default_factory=list)  # command-log key-values, in order

    @property
    def dt(self) -> float:
        return self.scene.dt


def load_run(reader: LogReader) -> RecordedRun:
    """Scene, command events and joint states of a node's log; LogFileError names what is missing."""
    meta = reader.metadata_record(FINGER_SIM_METADATA)
    missing = [k for k in REQUIRED_KEYS if k not in meta]
    if missing:
        raise LogFileError(reader.path, f"the {FINGER_SIM_METADATA!r} metadata record lacks {', '.join(missing)}: not a finger_node log?")
    scene = scene_from_dict(yaml.safe_load(meta["scene"]))
    run = RecordedRun(scene=scene, metadata=meta, torque_source=meta["torque_source"])
    js_topics = [t for t, info in reader.topics.items() if info.type == "sensor_msgs/msg/JointState"]
    log_topics = [t for t in reader.topics if t.endswith("/command_log")]
    reader.require_topics(js_topics[:1] or ["/joint_states"])
    for msg in reader.messages(js_topics + log_topics):
        if msg.topic in log_topics:
            run.events.append({kv.key: kv.value for kv in msg.msg.values})
        else:
            js = msg.msg
            order = [list(js.name).index(n) for n in JOINT_NAMES]
            stamp = js.header.stamp.sec * NS_PER_S + js.header.stamp.nanosec
            run.joint_states.append((stamp, tuple(float(js.position[i]) for i in order) + tuple(float(js.velocity[i]) for i in order)))
    return run


def trajectory_from_log(run: RecordedRun) -> Trajectory:
    """The recorded joint states as a Trajectory in the paper's coordinates (the simulate CSV's columns)."""
    p = run.scene.params
    q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
    system = run.scene.build_system()
    t, qs, vs = [], [], []
    for stamp, state in run.joint_states:
        q, v = paper_coordinates(state[:3], state[3:], q_ext, alpha)
        t.append(stamp / NS_PER_S)
        qs.append(q)
        vs.append(v)
    return Trajectory(
        t=np.array(t),
        q=np.array(qs).reshape(-1, 3),
        v=np.array(vs).reshape(-1, 3),
        energy=np.array([system.energy(q, v) for q, v in zip(qs, vs)]),
        residual=np.array([kinematics.constraint_norm(p, q) for q in qs]),
        method=run.metadata.get("method", run.scene.method),
        method_reason=run.metadata.get("method_reason", ""),
        wall_time=math.nan,
    )


@dataclass
class ResimResult:
    """Largest deviation of the re-simulated joint states from the recorded ones."""

    compared: int
    max_deviation: float  # over positions (rad) and velocities (rad/s)
    first_stamp_ns: int | None  # stamp of the first recorded state that differs, None if none

    @property
    def exact(self) -> bool:
        return self.first_stamp_ns is None

    def summary(self) -> str:
        if self.exact:
            return f"resim: {self.compared} recorded states reproduced bit for bit (max deviation 0)"
        return (
            f"resim: max deviation {self.max_deviation:.3e} over {self.compared} recorded states; "
            f"first at t = {self.first_stamp_ns / NS_PER_S:.6f} s on /clock"
        )


def resimulate(run: RecordedRun) -> ResimResult:
    """Re-run the log's scene, re-applying its torques at the steps they were applied, and
    compare every recorded joint state with the re-simulated one (exact comparison).

    Episodes: a reset restarts the scene at step 0; its states are stamped from the reset
    event's stamp on (the node's sim time never runs backwards). In topic mode the torque of
    step n is that of the last accepted/timeout/reset event of the episode with step ≤ n (0
    before any); in scene mode the scene's profile drives every step, as in the node.
    """
    sim = Simulator(run.scene)
    dt_ns = run.dt * NS_PER_S
    q_ext, alpha = kinematics.extended_pose(run.scene.params), kinematics.distal_offset(run.scene.params)
    offsets = [0] + [int(e["stamp_ns"]) for e in run.events if e.get("event") == "reset"]
    changes: dict[int, list[tuple[int, float]]] = {}
    for e in run.events:
        if e.get("event") in ("accepted", "timeout", "reset"):
            changes.setdefault(int(e["episode"]), []).append((int(e["step"]), float(e["torque"])))
    wanted: dict[int, dict[int, Vec6]] = {}  # episode → step → recorded state
    for stamp, state in run.joint_states:
        episode = max(i for i, off in enumerate(offsets) if off <= stamp)
        wanted.setdefault(episode, {})[round((stamp - offsets[episode]) / dt_ns)] = state
    compared, worst, first = 0, 0.0, None
    for episode in sorted(wanted):
        sim.reset()
        torques = sorted(changes.get(episode, []))
        held, k = 0.0, 0
        for n in range(max(wanted[episode]) + 1):
            if n in wanted[episode]:
                mine = joint_positions(sim.q, q_ext, alpha) + joint_velocities(sim.v)
                dev = max(abs(a - b) for a, b in zip(mine, wanted[episode][n]))
                compared += 1
                worst = max(worst, dev)
                if dev > 0.0 and first is None:
                    first = offsets[episode] + round(n * dt_ns)
            while k < len(torques) and torques[k][0] <= n:
                held = torques[k][1]
                k += 1
            sim.step(None if run.torque_source == "scene" else held)
    return ResimResult(compared, worst, first)
