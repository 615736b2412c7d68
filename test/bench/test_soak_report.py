"""finger_sim.bench.soak_report on a hand-made soak: every figure it prints against the one
worked out here from the rows written."""

from __future__ import annotations

from finger_sim.bench import soak_report

PROBE_HEADER = ("wall_s,pid,tid,proc,thread,cpu,policy,rtprio,run_ns,wait_ns,slices,minflt,majflt,"
                "vol_switches,forced_switches,steal_s,vm_majflt\n")


def test_report_on_a_hand_made_soak(tmp_path, capsys):
    # 100 windows after the warm-up: latest wake-ups 0.0, 0.1, ..., 9.9 ms, one of 42 ms at window 90 (RTF 0.958)
    t0 = 1000.0
    rows = ["sim_t_s,window_rtf,wall_s,late_wakeup_max_ms,dropped_steps\n"]
    for i in range(160):
        late = 42.0 if i == 150 else (i - 60) * 0.1 if i >= 60 else 1.0
        rtf = 0.958 if i == 150 else 1.0
        rows.append(f"{i:.3f},{rtf},{t0 + i:.3f},{late},0\n")
    windows = tmp_path / "soak_windows.csv"
    windows.write_text("".join(rows))
    # the node (pid 7, SCHED_FIFO): main thread 7, DDS thread 8 (many switches), stepping thread 9; the controller
    # (pid 20, SCHED_OTHER): thread 20; sampled at 0.5 s
    probe = [PROBE_HEADER]
    for k in range(330):
        t = t0 + 0.5 * k
        stall = 40e6 if t >= t0 + 149.5 else 0  # the stepping thread's run-queue wait jumps by 40 ms before window 150
        for tid, name, vol, run, wait, cpu in ((7, "python", 10 * k, 5e6 * k, 0, 0), (8, "dds.ev.0", 900 * k, 1e6 * k, 0, 1),
                                              (9, "python", 600 * k, 2e6 * k, stall, 1)):
            probe.append(f"{t:.3f},7,{tid},finger_sim.ros.node,{name},{cpu},1,20,{run:.0f},{wait:.0f},0,0,0,{vol},0,0.0,0\n")
        probe.append(f"{t:.3f},20,20,finger_sim.ros.pd_controller,python,0,0,0,{3e6 * k:.0f},0,0,0,0,{k},0,0.0,0\n")
    probe_csv = tmp_path / "probe.csv"
    probe_csv.write_text("".join(probe))
    assert soak_report.main(["--windows", str(windows), "--probe", str(probe_csv), "--late-ms", "10"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "100 windows after 60 s: 1 below 0.99, lowest 0.9580; steps dropped 0"
    # sorted: 0.0 .. 8.9 (90 of them, window 150's 9.0 replaced by 42), 9.1 .. 9.9, 42; p50 = 50th = 5.0
    assert out[1] == ("latest wake-up per window, ms: median 5.00, p90 9.10, p99 42.00, max 42.00; windows with one >= 5 ms: 50, "
                      ">= 10 ms: 1, >= 20 ms: 1")
    assert any(line.endswith("<- stepping") and " 9 " in line for line in out)
    # 164.5 s of samples: the node's three FIFO threads ran (5 + 1 + 2) ms per 0.5 s, the controller 3 ms per 0.5 s
    assert "CPU over the probe's 164.5 s, cores: real-time 0.016 (3 threads), normal 0.006 (1 threads)" in out
    late = [line for line in out if line.startswith("window at sim")]
    assert len(late) == 1 and "latest wake-up 42.0 ms" in late[0] and "run-queue wait 40.0 ms" in late[0]
    # samples at 149.0, 149.5 and 150.0 s fall in [end - 1.1 s, end + 0.05 s]: two intervals; CPU 0 has the main thread
    # (5 ms per interval), CPU 1 the other two (1 + 2 ms)
    assert "stepping thread over 1.00 s" in late[0] and late[0].endswith("real-time run per CPU, ms: cpu0 10, cpu1 6")


def test_trace_report_names_each_stall_and_the_threads_stopped_with_it(tmp_path, capsys):
    """--trace: collections per generation after the warm-up, and each wake-up >= --late-ms late with
    the cause its own columns give and the probe's threads whose run-queue wait grew >= 20 ms over it."""
    t0 = 1000.0
    windows = tmp_path / "soak_windows.csv"
    windows.write_text("sim_t_s,window_rtf,wall_s,late_wakeup_max_ms,dropped_steps\n"
                       + "".join(f"{i:.3f},1.0,{t0 + i:.3f},1.0,0\n" for i in range(160)))
    probe = [PROBE_HEADER]
    for k in range(330):
        t = t0 + 0.5 * k
        main_wait = 56e6 if t >= t0 + 120.5 else 0  # the executor (GIL holder) stopped 56 ms over stall B
        step_wait = 49e6 if t >= t0 + 100.5 else 0  # the stepping thread itself over stall A
        for tid, name, vol, wait in ((7, "python", 10 * k, main_wait), (8, "dds.ev.0", 900 * k, 0), (9, "python", 600 * k, step_wait)):
            probe.append(f"{t:.3f},7,{tid},finger_sim.ros.node,{name},0,1,20,{k * 1e6:.0f},{wait:.0f},0,0,0,{vol},0,0.0,0\n")
    probe_csv = tmp_path / "probe.csv"
    probe_csv.write_text("".join(probe))
    trace = tmp_path / "trace"
    trace.mkdir()
    (trace / "gc_7.csv").write_text("wall_s,generation,duration_ms,collected,thread\n"
                                    f"{t0 + 10},2,99.0,5,MainThread\n"  # in the warm-up: not counted
                                    f"{t0 + 70},2,12.0,5,MainThread\n{t0 + 80},1,0.5,0,Thread-3\n")
    (trace / "stalls_7.csv").write_text(
        "wall_s,late_ms,run_ms,runqueue_ms,blocked_ms,gc_ms,others\n"
        f"{t0 + 100.05},50.0,0.6,49.0,1.0,0.0,MainThread@executors.py:697\n"   # A: run queue
        f"{t0 + 120.06},55.0,2.5,0.1,54.9,0.0,MainThread@executors.py:697\n"   # B: blocked (the GIL)
        f"{t0 + 130.0},12.0,12.0,0.0,12.0,11.0,MainThread@executors.py:697\n"  # C: gc
        f"{t0 + 140.0},7.0,0.5,0.0,7.0,0.0,MainThread@executors.py:697\n")     # below --late-ms
    assert soak_report.main(["--windows", str(windows), "--probe", str(probe_csv), "--late-ms", "10", "--trace", str(trace)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert ("garbage collections written (gen 0 only when >= 0.5 ms): gen 1: 1, max 0.50 ms, total 0 ms; "
            "gen 2: 1, max 12.00 ms, total 12 ms") in out
    assert "wake-ups >= 10 ms late: 3; by cause: blocked 1, gc 1, run queue 1" in out
    stalls = [line for line in out if line.startswith("stall at")]
    assert len(stalls) == 3
    assert "50.0 ms late, cause run queue" in stalls[0] and stalls[0].endswith("over it: node:python/9 +49 ms")
    assert "55.0 ms late, cause blocked" in stalls[1] and stalls[1].endswith("over it: node:python/7 +56 ms")
    assert "12.0 ms late, cause gc" in stalls[2] and stalls[2].endswith("over it: none")
