"""finger_node crushes an object (a `break_force` exceeded), in its own process over real DDS.

References: `simulate` of the same scene with the object unbreakable (its grip force up to the
crush, and the first step at which it exceeds the break force), read against the node's log with
rosbags (someone else's MCAP reader); the log's own states after the crush (no force, the finger
closing on through the object's place); `finger-sim resim` and `finger-sim info` as a user runs them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy")

from rosbags.highlevel import AnyReader  # noqa: E402

from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import simulate  # noqa: E402
from helpers import NODE  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: N: below the force with which the cup scene's finger comes to rest on it (≈ 0.17 N), so it breaks.
BREAK_FORCE = 0.1
SUBPROCESS_TIMEOUT_S = 120.0
STEP_NS = 1_000_000  # the scene's dt, 1 ms


def fragile_scene(tmp_path: Path, break_force: float | None) -> Path:
    data = yaml.safe_load((CONFIG / "grasp_cylinder.yaml").read_text())
    if break_force is not None:
        data["objects"][0]["break_force"] = break_force
    path = tmp_path / ("fragile.yaml" if break_force is not None else "sturdy.yaml")
    path.write_text(yaml.safe_dump(data))
    return path


def by_topic(path: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message of the log as (log time ns, message), by topic (rosbags)."""
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path]) as reader:
        for c, t, raw in reader.messages():
            out.setdefault(c.topic, []).append((t, reader.deserialize(raw, c.msgtype)))
    return out


def finger_sim(*args: str) -> subprocess.CompletedProcess:
    cli = [sys.executable, "-c", "import sys; from finger_sim.cli import main; sys.exit(main())"]
    return subprocess.run([*cli, *args], capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)


def test_node_crushes_an_object_records_it_and_resims_it_bit_for_bit(launcher, tmp_path):
    scene = fragile_scene(tmp_path, BREAK_FORCE)
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(scene), torque_source="scene", realtime_factor=0.0, record_dir=str(bags)))
    assert node.wait(SUBPROCESS_TIMEOUT_S) == 0, node.output()
    (path,) = sorted(bags.glob("*.mcap"))
    topics = by_topic(path)

    # the reference: the same scene with an unbreakable cup, offline
    sturdy = simulate(load_scene(fragile_scene(tmp_path, None)))
    force_ref = sturdy.outputs["grip_force"]
    step = next(k for k, f in enumerate(force_ref) if f > BREAK_FORCE)  # the state at which the cup breaks

    (record,) = [m for _, m in topics["/finger_node/crush_log"]]
    values = {kv.key: kv.value for kv in record.values}
    assert (values["event"], values["object"], values["episode"], values["step"]) == ("crushed", "cup", "0", str(step))
    assert float(values["force"]) == force_ref[step] and float(values["break_force"]) == BREAK_FORCE
    assert float(values["t"]) == pytest.approx(step * 1e-3, abs=1e-15)
    assert "crushed" in record.message and "cup" in record.message
    assert f"object 'cup' crushed at t = {step * 1e-3:.6g} s" in node.output()  # the node's log line

    # grip force by state (log time = sim time): the uncrushed run up to the crush, then nothing
    force = {t // STEP_NS: m.data for t, m in topics["/grip_force"]}
    assert [force[k] for k in range(step + 1)] == force_ref[: step + 1].tolist()
    assert all(force[k] == 0.0 for k in range(step + 1, len(force)))
    # the finger, still driven, closes on through where the cup was (the sturdy run rests on it)
    theta = [m.position[0] for _, m in topics["/joint_states"]]
    assert len(theta) == len(sturdy.t)
    assert theta[-1] > sturdy.q[-1, 0] + 0.1  # rad

    # /diagnostics (logged) counts the crush
    last = topics["/diagnostics"][-1][1].status[0]
    diag = {kv.key: kv.value for kv in last.values}
    assert diag["objects_crushed"] == "1" and "cup" in diag["last_crush"] and "objects crushed" in last.message

    resim = finger_sim("resim", str(path))
    assert resim.returncode == 0, resim.stdout + resim.stderr
    assert "bit for bit" in resim.stdout and f"object 'cup' crushed at step {step} of episode 0" in resim.stdout
    info = finger_sim("info", str(path))
    assert info.returncode == 0, info.stdout + info.stderr
    assert f"/finger_node/crush_log: episode 0, step {step}: object 'cup' crushed" in info.stdout
