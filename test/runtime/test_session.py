"""The stepping session (finger_sim.runtime.session) and the log assembly (runtime.recording), without DDS.

A session is driven here directly, in the test's thread, with the real fingers of the node
(finger_sim.ros.finger: rclpy's message classes, no middleware): its publishes are collected.
References: a Simulator of the same scene stepped by hand (bit for bit), the time grid
(step·dt), the scene's duration, and the log read back by mcap's reader (LogReader) and rosbags.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rclpy")

from finger_sim.log import LogReader  # noqa: E402
from finger_sim.ros.finger import Finger  # noqa: E402
from finger_sim.ros.interfaces import OUTPUTS, Endpoint  # noqa: E402
from finger_sim.run_log import FINGER_SIM_METADATA  # noqa: E402
from finger_sim.runtime.diagnostics import Level  # noqa: E402
from finger_sim.runtime.hand_config import FingerSpec  # noqa: E402
from finger_sim.runtime.log_paths import UnwritableLog  # noqa: E402
from finger_sim.runtime.parameters import NodeSettings  # noqa: E402
from finger_sim.runtime.recording import Channel, open_run_log  # noqa: E402
from finger_sim.runtime.session import RunState, SteppingSession  # noqa: E402
from finger_sim.runtime.simulator import node_simulator  # noqa: E402
from finger_sim.runtime.timeline import Timeline  # noqa: E402
from finger_sim.scene_paths import resolve_scene  # noqa: E402

RATE_HZ = 1000.0
DT_NS = 1_000_000
TORQUE = 0.004  # N·m, held by the scripted scene below


class _Logger:
    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def __getattr__(self, level: str) -> Any:
        return lambda text, **_: self.lines.append((level, text))


class Session(SteppingSession):
    """A session whose output is collected: (topic, stamp ns, message) per publish."""

    def __init__(self, **values: Any) -> None:
        settings = NodeSettings.from_values({"physics_rate_hz": RATE_HZ, **values})
        timeline = Timeline(1.0 / RATE_HZ)
        self.logger = _Logger()
        self.published: list[tuple[str, int]] = []
        self.events: list[str] = []
        self._clock_out = None
        finger = Finger(FingerSpec("", resolve_scene(settings.scene), ""), settings, timeline)
        outputs = {key: Endpoint(None, spec.topic, spec.msg_type, False) for key, spec in OUTPUTS.items() if spec.per_finger}
        finger.connect("/session_test", outputs, [])
        self._start_session("session_test", settings, timeline, [finger])

    def get_logger(self) -> _Logger:
        return self.logger

    def _publish(self, out: Endpoint, msg: Any) -> None:
        self.published.append((out.topic, self.stamp_ns))

    def _publish_clock(self, stamp: int) -> None:
        self.published.append(("/clock", stamp))

    def _publish_diagnostics(self) -> None:
        self.reports = self._reports(None)

    def _event(self, finger: Any, event: Any, level: Level = Level.OK) -> None:
        self.events.append(event.event)

    def _log_parameter_change(self, params: Any) -> None:
        pass

    def stamps(self, topic: str) -> list[int]:
        return [stamp for t, stamp in self.published if t == topic]


def scripted_scene(tmp_path: Path, duration: float) -> Path:
    """finger_default under a constant TORQUE for `duration` s."""
    text = resolve_scene("finger_default").read_text()
    assert "torque: {type: constant, value: 0.0}" in text and "duration: 3600.0" in text
    path = tmp_path / "held.yaml"
    path.write_text(text.replace("torque: {type: constant, value: 0.0}", f"torque: {{type: constant, value: {TORQUE}}}")
                    .replace("duration: 3600.0", f"duration: {duration}"))
    return path


def test_steps_equal_a_simulator_stepped_by_hand_and_end_with_the_scene(tmp_path: Path) -> None:
    scene, steps = scripted_scene(tmp_path, 0.05), 50
    session = Session(scene=str(scene), torque_source="scene", realtime_factor=0.0)
    session._publish_state(force=True)
    advanced = 0
    while session._advance():
        advanced += 1
    assert advanced + 1 == steps  # the last step ends the scene
    assert session.state is RunState.FINISHED and session.done.result(0) == 0
    reference = node_simulator(scene, RATE_HZ)
    for _ in range(steps):
        reference.step(None)
    finger = session.fingers[0]
    assert np.array_equal(finger.sim.q, reference.sim.q) and np.array_equal(finger.sim.v, reference.sim.v)
    assert finger.applied == TORQUE
    assert session.stamps("joint_states") == [n * DT_NS for n in range(steps + 1)]
    assert session.stamps("/clock") == [n * DT_NS for n in range(steps + 1)]
    assert session.steps_total == steps


def test_publish_rate_decimates_on_the_time_grid(tmp_path: Path) -> None:
    session = Session(scene=str(scripted_scene(tmp_path, 0.1)), torque_source="scene", publish_rate_hz=100.0)
    session._publish_state(force=True)
    while session._advance():
        pass
    assert session.stamps("joint_states") == [n * 10 * DT_NS for n in range(11)]  # every 10th of 100 steps


def test_pause_step_and_reset() -> None:
    session = Session(steps_per_trigger=7, start_paused=True)
    session._publish_state(force=True)
    assert session.state is RunState.PAUSED
    ok, where = session._step_while_paused()
    assert ok and "step=7 " in where and session.sim.step_index == 7
    assert session.stamps("joint_states") == [n * DT_NS for n in range(8)]  # each state once, publishing every step
    assert session._pause(False) == (True, f"running; {session._where()}")
    for _ in range(5):
        session._advance()
    assert session.sim.step_index == 12 and session.stamp_ns == 12 * DT_NS
    ok, where = session._step_while_paused()
    assert not ok and where.startswith("running: ~/step works while paused")
    initial = node_simulator(session.fingers[0].spec.scene_path, RATE_HZ)
    ok, where = session._reset()
    assert ok and "step=0 " in where and "episode=1" in where and session.events == ["reset"]
    assert np.array_equal(session.sim.q, initial.sim.q) and session.sim.step_index == 0
    assert session.stamp_ns == 13 * DT_NS  # /clock goes on: step 0 of the new episode one dt after the last
    session._advance()
    assert session.stamps("joint_states")[-2:] == [13 * DT_NS, 14 * DT_NS]


def test_a_finished_run_refuses_to_resume_until_reset(tmp_path: Path) -> None:
    session = Session(scene=str(scripted_scene(tmp_path, 0.01)), torque_source="scene", exit_at_end=False)
    while session._advance():
        pass
    assert session.state is RunState.FINISHED and not session.done.done()  # exit_at_end false: the node stays
    ok, message = session._pause(False)
    assert not ok and message.startswith("finished: call ~/reset to run again")
    assert session._reset()[0] and session.state is RunState.RUNNING


def test_the_log_holds_its_channels_and_each_fingers_run(tmp_path: Path) -> None:
    session = Session(record_dir=str(tmp_path / "bags"))
    channels = [Channel("/joint_states", "sensor_msgs/msg/JointState"), Channel("/clock", "rosgraph_msgs/msg/Clock")]
    log = open_run_log(session.settings, "paper", "", session.fingers, channels, on_problem=pytest.fail)
    log.close()
    assert log.path.parent == tmp_path / "bags" and log.path.name.startswith("paper_")
    reader = LogReader(log.path)
    assert sorted(c.topic for c in reader.channels.values()) == ["/clock", "/joint_states"]
    meta = reader.metadata_record(FINGER_SIM_METADATA)
    assert meta["method"] == session.sim.method
    assert reader.dropped == 0


def test_no_log_folder_means_an_unwritable_log_that_says_why(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    session = Session(record_dir=str(tmp_path / "file"))
    log = open_run_log(session.settings, "paper", "", session.fingers, [], on_problem=pytest.fail)
    assert isinstance(log, UnwritableLog) and str(tmp_path / "file") in log.error


class _FakeClock:
    """perf_counter for the session module: wall s that only the test moves."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


@pytest.mark.parametrize("where", ["sleep", "step"])
def test_a_stall_at_a_window_end_is_caught_up_before_the_report(monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    """Paced at 1 kHz on a fake wall clock, 0.1 s off the CPU across the end of the first 1 s
    window (in the sleep before a step, or within a step): the backlog (within catchup_limit)
    runs before /diagnostics reports, so the windows read steps × dt / wall s = 1.0 each and
    nothing is dropped; the reference is the wall time × rate. Before, the first window read ~0.9."""
    import finger_sim.runtime.session as session_module

    clock = _FakeClock()
    monkeypatch.setattr(session_module, "time", clock)
    reports: list[dict] = []
    stall_at, stall_s, end = 0.98, 0.1, 2.5

    class Stalled(Session):
        def _sleep(self, timeout: float) -> None:
            late = stall_s if where == "sleep" and clock.now < stall_at <= clock.now + timeout else 0.0
            clock.now += max(timeout, 0.0) + late
            if clock.now >= end:
                self.stop()

        def _advance(self) -> bool:
            if where == "step" and clock.now < stall_at <= clock.now + 1e-3:
                clock.now += stall_s  # this step waited on a lock
            return super()._advance()

        def _publish_diagnostics(self) -> None:
            reports.append(self._reports(None)[0][2])

    session = Stalled(realtime_factor=1.0, record=False)
    session.fingers[0].diagnostics.restart(0.0)
    session._loop()
    assert len(reports) == 2 and session.pacer is not None and session.pacer.dropped_steps == 0
    assert [r["realtime_factor"] for r in reports] == pytest.approx([1.0, 1.0], abs=2e-3)
    assert session.steps_total == pytest.approx(clock.now * RATE_HZ, abs=2)
