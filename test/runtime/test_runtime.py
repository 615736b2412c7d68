"""finger_sim.runtime: the node's ROS-free parts, checked on numbers without DDS.

References: hand-computed wall-time grids (pacing), the step arithmetic of command_timeout
(ceil(timeout/dt)), the parameter table's declared ranges, and the file system itself (log paths).
"""

from __future__ import annotations

import ast
import math
from datetime import datetime, timezone
from pathlib import Path

import pytest

import finger_sim.runtime
from finger_sim.errors import ConfigError
from finger_sim.run_log import CommandEvent
from finger_sim.runtime.commands import REFUSED_NOT_FINITE, REFUSED_SCENE, Inbox, TorqueCommands, timeout_steps
from finger_sim.log import RecorderCpu
from finger_sim.runtime.diagnostics import ClockWatch, DiagnosticsWindow, Level, LogStatus, Snapshot
from finger_sim.runtime.log_paths import LogFolder, UnwritableLog, create_log_file, safe_component
from finger_sim.runtime.pacing import CATCHUP_LIMIT_S, Lateness, Pacer
from finger_sim.runtime.parameters import NODE_PARAMETERS, RUNTIME_PARAMETERS, CommandQos, NodeSettings, Param, ParameterError, TorqueSource
from finger_sim.runtime.timeline import Timeline

DT = 1e-3
STARTED = datetime(2024, 1, 2, 3, 4, 5, 678000, tzinfo=timezone.utc)


# -- isolation -------------------------------------------------------------------------------
def test_runtime_imports_no_ros_or_mcap():
    forbidden = ("rclpy", "rcl_interfaces", "std_msgs", "sensor_msgs", "diagnostic_msgs", "mcap", "finger_sim.ros",
                 "finger_sim.log")
    for path in Path(finger_sim.runtime.__file__).parent.glob("*.py"):
        if path.name == "recording.py":  # the one module that records: it assembles the MCAP log (test_layers)
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module] if isinstance(node, ast.ImportFrom) and node.module else []
            assert not [n for n in names if n.startswith(forbidden)], (path.name, names)


# -- pacing ----------------------------------------------------------------------------------
def test_pacing_due_steps_from_wall_times():
    """realtime_factor 2 at dt 1 ms: a step every 0.5 ms of wall time, step 1 due at the first tick."""
    p = Pacer(DT, 2.0, catchup_limit_s=0.05)
    assert p.wall_per_step == 0.0005 and p.catchup_steps == 100  # 50 ms of backlog
    assert p.due(10.0) == 1  # anchor = 10.0 − 0.0005: step 1 due now
    assert p.next_due == pytest.approx(10.0005, abs=1e-12)
    assert p.due(10.0003) == 0  # early: sleep
    assert p.due(10.0005) == 1  # on time
    assert p.due(10.0021) == 3  # steps 3, 4, 5 due (at 10.001, 10.0015, 10.002): one overrun
    assert p.overruns == 1 and p.dropped_steps == 0
    assert p.lateness.n == 3 and p.lateness.max == pytest.approx(0.0011, abs=1e-12)
    assert p.next_due == pytest.approx(10.0025, abs=1e-12)


def test_pacing_drops_a_backlog_beyond_the_catchup_limit():
    p = Pacer(DT, 1.0, catchup_limit_s=0.05)  # 1 ms per step, catch up at most 50 steps
    assert p.due(0.0) == 1
    assert p.due(0.2) == 50  # 200 steps due: 150 dropped, 50 run
    assert (p.dropped_steps, p.overruns) == (150, 1)
    assert p.next_due == pytest.approx(0.201, abs=1e-12)  # the anchor slipped by the dropped steps
    assert p.due(0.201) == 1 and p.dropped_steps == 150


def paced_run(pacer: Pacer, wall_s: float, stall: tuple[float, float], tick_s: float = 1e-4) -> int:
    """Steps `pacer` hands out to a loop that ticks every `tick_s` wall s from 0 to `wall_s` but
    is off its CPU over stall = (start, end) wall s (its first tick after the stall is at `end`);
    the last tick is half a tick after `wall_s`, clear of the float edge of the step grid."""
    steps = 0
    for i in range(round(wall_s / tick_s) + 1):
        now = (i + 0.5) * tick_s if i == round(wall_s / tick_s) else i * tick_s
        if not stall[0] + tick_s / 2 < now < stall[1] - tick_s / 2:
            steps += pacer.due(now)
    return steps


@pytest.mark.parametrize("stall_s", [0.07, 0.08, 0.1, 0.2])
def test_pacing_catches_up_a_stall_within_the_default_limit(stall_s):
    """The soak's stalls (70-100 ms, up to 0.2 s): run in one burst, nothing dropped, so the steps
    at the end equal wall time × rate (+1: step 1 is due at t = 0), as without a stall."""
    p = Pacer(DT, 1.0)
    assert p.catchup_limit_s == CATCHUP_LIMIT_S == 0.25 and p.catchup_steps == 250
    assert paced_run(p, 1.0, (0.5, 0.5 + stall_s)) == 1001
    assert p.dropped_steps == 0 and p.lateness.max == pytest.approx(stall_s - 1e-3, abs=2e-4)
    assert p.overruns == 1  # the burst is counted, not hidden


def test_pacing_drops_only_the_backlog_beyond_the_limit():
    """A 0.4 s stall with a 0.25 s limit: 0.15 s of steps dropped and counted, sim time slips by as much."""
    p = Pacer(DT, 1.0)
    steps = paced_run(p, 1.0, (0.5, 0.9))
    assert p.dropped_steps == pytest.approx(150, abs=1) and steps + p.dropped_steps == 1001


def test_a_caught_up_stall_keeps_the_diagnostics_window_at_real_time():
    """/diagnostics' window real-time factor (steps × dt / wall s of the window) over 1 s holding an
    80 ms stall: 1.0 when it is caught up (the default), 0.97 when the old 50 ms limit drops 30 steps."""
    for limit, rtf in ((CATCHUP_LIMIT_S, 1.0), (0.05, 0.97)):
        p = Pacer(DT, 1.0, catchup_limit_s=limit)
        first = paced_run(p, 1.0, (0.0, 0.0))  # the first second: no stall (steps 1..1001)
        window = DiagnosticsWindow(now=1.0)
        window.report(snapshot(steps_total=first), commands(), p, now=1.0)
        steps = first
        for i in range(1, 1001):  # the second second, ticking every ms but off CPU from 1.4 s to 1.48 s
            if not 400 < i < 480:
                steps += p.due(1.0 + i * 1e-3)
        _, _, values = window.report(snapshot(steps_total=steps), commands(), p, now=2.0)
        assert values["realtime_factor"] == pytest.approx(rtf, abs=1e-9)
        assert values["dropped_steps"] == round((1 - rtf) * 1000)


def test_pacing_restart_and_windows():
    p = Pacer(DT, 1.0)
    p.due(5.0)
    p.due(5.003)  # 3 due
    p.restart()
    assert p.due(100.0) == 1  # a new run: step 1 due at once, no backlog from the pause
    assert p.overruns == 1 and p.window.n == 3
    p.new_window()
    assert p.window.n == 0 and p.lateness.n == 3
    with pytest.raises(ConfigError, match="realtime_factor"):
        Pacer(DT, 0.0)


def test_lateness_percentile_is_the_bin_edge():
    late = Lateness()
    for i in range(100):
        late.add(i * 1e-5 + 5e-6)  # one sample per 10 µs bin, in the middle
    assert late.percentile(99) == pytest.approx(99 * Lateness.BIN_S, abs=1e-15)
    assert late.percentile(100) == late.max == pytest.approx(99.5e-5)
    assert Lateness().percentile(99) == 0.0


# -- commands --------------------------------------------------------------------------------
def commands(**kw) -> TorqueCommands:
    args = dict(max_torque=0.01, command_timeout=0.05, accepting=True) | kw
    return TorqueCommands(Timeline(DT), **args)


def test_commands_saturate_and_take_effect_at_the_next_step():
    c = commands()
    assert c.take("/motor_torque", (1e9,), 7) is None
    assert c.held == 0.0
    torque, event = c.torque_for_step(7)
    assert torque == 0.01 and c.command_step == 7
    assert event == CommandEvent(event="accepted", step=7, episode=0, stamp_ns=7_000_000, torque=0.01,
                                 requested="1000000000.0", source="/motor_torque", saturated=True)
    assert c.take("/effort_commands", (-0.004,), 9) is None
    assert c.torque_for_step(9)[1].torque == -0.004
    assert c.torque_for_step(9)[1] is None  # held, no change, no event
    c.take("/motor_torque", (-0.004,), 10)
    assert c.torque_for_step(10) == (-0.004, None)  # the same torque again: no event, but it re-arms the timeout
    assert (c.counts.accepted, c.counts.saturated) == (3, 1)


def test_commands_time_out_at_exactly_the_step():
    """command_timeout 0.05 s at dt 1 ms: 50 steps after the step a command took effect."""
    assert timeout_steps(0.05, DT) == 50 and timeout_steps(0.0015, DT) == 2 and timeout_steps(0.0, DT) is None
    c = commands()
    c.take("/motor_torque", (0.003,), 100)
    c.torque_for_step(100)
    for n in range(101, 150):
        assert c.torque_for_step(n) == (0.003, None), n
    torque, event = c.torque_for_step(150)
    assert torque == 0.0 and c.counts.timeouts == 1
    assert (event.event, event.step, event.torque, event.reason) == ("timeout", 150, 0.0, "no command for 0.05 s of sim time")
    assert c.torque_for_step(151) == (0.0, None)  # no second timeout
    forever = commands(command_timeout=0.0)
    forever.take("/motor_torque", (0.003,), 0)
    forever.torque_for_step(0)
    assert forever.torque_for_step(10**6) == (0.003, None)


def test_commands_refusal_reasons():
    c = commands()
    c.take("/motor_torque", (0.002,), 3)
    c.torque_for_step(3)
    cases = [((math.nan,), REFUSED_NOT_FINITE, "nan"), ((-math.inf,), REFUSED_NOT_FINITE, "-inf"),
             ((0.001, 0.002), "expected exactly 1 element, got 2", "0.001, 0.002"), ((), "expected exactly 1 element, got 0", "")]
    for values, reason, requested in cases:
        event = c.take("/effort_commands", values, 5)
        assert (event.event, event.step, event.reason, event.requested, event.torque) == ("refused", 5, reason, requested, 0.002)
    assert c.counts.refused == 4 and c.counts.accepted == 1
    assert c.torque_for_step(5) == (0.002, None)  # refusals change nothing
    scene = commands(accepting=False)
    assert scene.take("/motor_torque", (0.001,), 0).reason == REFUSED_SCENE
    assert scene.torque_for_step(0) == (None, None)  # the scene's profile


def test_commands_reset_and_stamps_across_episodes():
    timeline = Timeline(DT)
    c = TorqueCommands(timeline, max_torque=0.05, command_timeout=0.5, accepting=True)
    c.take("/motor_torque", (0.003,), 0)
    c.torque_for_step(0)
    timeline.new_episode(last_stamp_ns=timeline.stamp(250))
    event = c.reset("~/reset")
    assert (event.event, event.episode, event.step, event.stamp_ns, event.torque) == ("reset", 1, 0, 251_000_000, 0.0)
    assert c.held == 0.0 and c.command_step is None
    assert timeline.stamp(3) == 254_000_000


def test_inbox_counts_what_arrived():
    box = Inbox()
    for i in range(5):
        box.put("/motor_torque", [float(i)])
    assert box.received == 5 and bool(box)
    assert [v for _, v, _ in box.drain()] == [(0.0,), (1.0,), (2.0,), (3.0,), (4.0,)]
    assert not box and box.received == 5


# -- parameters ------------------------------------------------------------------------------
def test_node_settings_defaults_and_rules():
    s = NodeSettings.from_values({})
    assert (s.physics_rate_hz, s.torque_source, s.command_qos, s.command_depth) == (1000.0, TorqueSource.TOPIC,
                                                                                  CommandQos.SYSTEM_DEFAULT, 1000)
    assert s.to_values()["torque_source"] == "topic" and set(s.to_values()) == {p.name for p in NODE_PARAMETERS}
    assert NodeSettings.from_values({"command_qos": "reliable"}).command_qos is CommandQos.RELIABLE
    assert NodeSettings.from_values({"physics_rate_hz": 500}).physics_rate_hz == 500.0  # an int for a float (issue 19)
    bad = [
        ({"physics_rate_hz": "500"}, "parameter 'physics_rate_hz': expected type float, got '500'"),
        ({"physics_rate_hz": -5.0}, "parameter 'physics_rate_hz': expected a value in [1, 100000], got -5.0"),
        ({"command_depth": 0}, "parameter 'command_depth': expected a value in [1, 100000], got 0"),
        ({"torque_source": "joystick"}, "parameter 'torque_source': expected one of ['topic', 'scene'], got 'joystick'"),
        ({"command_qos": "best"}, "parameter 'command_qos': expected one of ['system_default', 'reliable'], got 'best'"),
        ({"publish_rate_hz": 2000.0}, "parameter 'publish_rate_hz': expected 0 or a rate ≤ physics_rate_hz (1000 Hz), got 2000.0"),
        ({"frame_prefix": "a b"}, "parameter 'frame_prefix': expected a prefix without white space, got 'a b'"),
        ({"record": 1}, "parameter 'record': expected type bool, got 1"),
        ({"no_such": 1.0}, "parameter 'no_such': expected one of"),
    ]
    for values, message in bad:
        with pytest.raises(ParameterError) as info:
            NodeSettings.from_values(values)
        assert str(info.value).startswith(message), str(info.value)


def test_parameter_table_is_consistent():
    for p in NODE_PARAMETERS:
        assert p.check(p.default) == p.default  # every default passes its own checks
        assert p.read_only == (p.name not in RUNTIME_PARAMETERS)
        if p.range is not None:
            assert p.range[0] <= p.default <= p.range[1]
    assert Param("k", 1.0, "", (0.0, 2.0)).check(2.0) == 2.0  # inclusive


# -- diagnostics -----------------------------------------------------------------------------
def snapshot(**kw) -> Snapshot:
    base = dict(state="running", diverged=False, scene="s", scene_file="s.yaml", method="rk4", dt=DT, dt_source="",
                torque_source="topic", clock_s=1.0, time_s=1.0, step=1000, episode=0, realtime_factor_target=1.0,
                steps_total=1000, run_wall_s=2.0, max_residual_m=1e-15, torque=0.0, commands_received=7,
                log=LogStatus("bags/x.mcap", written=10))
    return Snapshot(**(base | kw))


def test_diagnostics_levels_and_counts():
    c = commands()
    window = DiagnosticsWindow(now=0.0)
    level, message, values = window.report(snapshot(), c, None, now=0.5)
    assert (level, message) == (Level.OK, "running")
    assert values["realtime_factor"] == pytest.approx(2.0) and values["realtime_factor_mean"] == 0.5
    assert (values["commands_received"], values["log_error"], values["clock_publishers"]) == (7, "none", "not publishing")

    failed = LogStatus("bags/x.mcap", written=0, dropped=1234, error="cannot create a log: Not a directory")
    level, message, values = window.report(snapshot(log=failed), c, None, now=1.5)
    assert level == Level.ERROR
    assert message == "running; log failed: cannot create a log: Not a directory; 1234 messages lost"
    assert (values["log_messages_dropped"], values["log_error"]) == (1234, failed.error)

    level, message, _ = window.report(snapshot(log=LogStatus("bags/x.mcap", written=900, dropped=12)), c, None, now=2.5)
    assert (level, message) == (Level.WARN, "running; log incomplete: 12 messages lost")

    level, message, values = window.report(snapshot(clock_publishers=2), c, None, now=3.5)
    assert level == Level.WARN and "2 publishers on /clock" in message and values["clock_publishers"] == 2

    c.take("/motor_torque", (math.nan,), 0)
    pacer = Pacer(DT, 1.0, catchup_limit_s=0.05)
    pacer.due(0.0)
    pacer.due(0.2)  # 150 steps dropped
    level, message, values = window.report(snapshot(), c, pacer, now=4.5)
    assert (level, message) == (Level.WARN, "running; 1 commands refused, 150 steps dropped in the last 1.0 s")
    assert (values["dropped_steps"], values["overruns"], values["late_wakeups_total"]) == (150, 1, 2)
    assert values["late_wakeup_max_ms"] == pytest.approx(199.0) and pacer.window.n == 0  # a new window
    level, message, _ = window.report(snapshot(), c, pacer, now=5.5)
    assert (level, message) == (Level.OK, "running")  # nothing new in this window
    assert window.report(snapshot(state="diverged", diverged=True), c, None, now=6.5)[0] == Level.ERROR


def test_diagnostics_report_recording_cpu_per_window():
    """log_cpu_*: the recorder's totals as read, and each window's growth over the sim time it advanced
    (hand-computed here); 0 without a log and while sim time stands still."""
    c = commands()
    window = DiagnosticsWindow(now=0.0)
    _, _, values = window.report(snapshot(log=LogStatus(None), steps_total=1000), c, None, now=1.0)
    assert [values[k] for k in ("log_cpu_per_sim_s", "log_cpu_s", "log_cpu_caller_s", "log_cpu_threads_s",
                                "log_cpu_writer_s")] == [0.0] * 5
    first = RecorderCpu(caller_s=0.004, threads_s=0.002, writer_s=0.25)  # the writer's start-up is in its total
    _, _, values = window.report(snapshot(log=LogStatus("x.mcap", cpu=first), steps_total=3000), c, None, now=3.0)
    assert values["log_cpu_s"] == pytest.approx(0.256) and values["log_cpu_writer_s"] == 0.25
    assert values["log_cpu_per_sim_s"] == pytest.approx(0.256 / (2000 * DT))
    later = RecorderCpu(caller_s=0.010, threads_s=0.004, writer_s=0.256)  # +0.014 CPU s in 500 steps
    _, _, values = window.report(snapshot(log=LogStatus("x.mcap", cpu=later), steps_total=3500), c, None, now=3.5)
    assert values["log_cpu_per_sim_s"] == pytest.approx(0.014 / (500 * DT))
    assert (values["log_cpu_caller_s"], values["log_cpu_threads_s"]) == (0.010, 0.004)
    _, _, values = window.report(snapshot(log=LogStatus("x.mcap", cpu=later), steps_total=3500), c, None, now=4.5)
    assert values["log_cpu_per_sim_s"] == 0.0  # paused: no sim time in the window


# -- log paths -------------------------------------------------------------------------------
@pytest.mark.parametrize("name, expected", [
    ("paper_flexion", "paper_flexion"), ("../X", "___X"), ("/tmp/X", "_tmp_X"), (".hidden", "_hidden"),
    ("a b/c\\d:é", "a_b_c_d__"), ("..", "__"), ("x" * 300, "x" * 64),
])
def test_safe_component(name, expected):
    assert safe_component(name) == expected


@pytest.mark.parametrize("scene", ["../X", "/tmp/X", "../../etc/passwd", "..", ""])
def test_log_file_stays_inside_record_dir(tmp_path, scene):
    folder = LogFolder.make(str(tmp_path / "bags"))
    path = folder.new_file(scene, "index", started=STARTED)
    assert path.parent == (tmp_path / "bags").resolve() and path.is_file()
    assert path.name.endswith("index_20240102T030405.678Z.mcap") and not path.name.startswith(".")
    again = folder.new_file(scene, "index", started=STARTED)  # the same millisecond: a new name
    assert again != path and again.parent == path.parent
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bags"]


def test_record_dir_with_dotdot_creates_only_the_normalized_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    folder = LogFolder.make("missing/deeper/../../logs/run")
    assert folder.path == tmp_path.resolve() / "logs" / "run"
    assert folder.created == [tmp_path.resolve() / "logs", tmp_path.resolve() / "logs" / "run"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs"]  # no empty 'missing'
    folder.remove_created()
    assert list(tmp_path.iterdir()) == []


def test_unwritable_record_dir_leaves_nothing(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("a regular file")
    with pytest.raises(OSError):
        LogFolder.make(str(afile / "bags"))
    with pytest.raises(OSError):
        LogFolder.make("/proc/finger_sim_no_such/bags")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]
    log = UnwritableLog(str(afile / "bags"), "cannot create a log")
    assert log.write("/joint_states", b"", 0) is False and (log.written, log.dropped) == (0, 1)
    assert log.write_records(["/clock", "/joint_states"], [b"", b""], 0) == 0 and (log.written, log.dropped) == (0, 3)



def test_create_log_file_makes_only_what_it_needs(tmp_path):
    """An existing parent is kept; under a regular file nothing is made and the file stays."""
    (tmp_path / "x").mkdir()  # an existing parent is kept
    started = STARTED
    path = create_log_file(str(tmp_path / "x" / "new"), "s", started=started)
    assert path.parent == (tmp_path / "x" / "new").resolve()
    path.unlink()
    (tmp_path / "x" / "new").rmdir()
    blocker = tmp_path / "x" / "new"
    blocker.write_text("")  # a file where the folder should go
    with pytest.raises(OSError):
        create_log_file(str(blocker / "deeper" / "bags"), "s", started=started)
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == ["new"] and blocker.is_file()


def test_clock_watch_warns_once_about_another_clock_publisher():
    watch = ClockWatch()
    assert [watch.warning(n) for n in (0, 1, 1)] == [None, None, None]  # not publishing yet, or alone
    first = watch.warning(2)
    assert first is not None and first.startswith("2 publishers on /clock") and "publish_clock:=false" in first
    assert [watch.warning(n) for n in (3, 1, 2)] == [None, None, None]  # said once per run
