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
    # the node (pid 7): main thread 7, DDS thread 8 (many switches), stepping thread 9; sampled at 0.5 s
    probe = [PROBE_HEADER]
    for k in range(330):
        t = t0 + 0.5 * k
        stall = 40e6 if t >= t0 + 149.5 else 0  # the stepping thread's run-queue wait jumps by 40 ms before window 150
        for tid, name, vol, run, wait, cpu in ((7, "python", 10 * k, 5e6 * k, 0, 0), (8, "dds.ev.0", 900 * k, 1e6 * k, 0, 1),
                                              (9, "python", 600 * k, 2e6 * k, stall, 1)):
            probe.append(f"{t:.3f},7,{tid},finger_sim.ros.node,{name},{cpu},1,20,{run:.0f},{wait:.0f},0,0,0,{vol},0,0.0,0\n")
    probe_csv = tmp_path / "probe.csv"
    probe_csv.write_text("".join(probe))
    assert soak_report.main(["--windows", str(windows), "--probe", str(probe_csv), "--late-ms", "10"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "100 windows after 60 s: 1 below 0.99, lowest 0.9580; steps dropped 0"
    # sorted: 0.0 .. 8.9 (90 of them, window 150's 9.0 replaced by 42), 9.1 .. 9.9, 42; p50 = 50th = 5.0
    assert out[1] == ("latest wake-up per window, ms: median 5.00, p90 9.10, p99 42.00, max 42.00; windows with one >= 5 ms: 50, "
                      ">= 10 ms: 1, >= 20 ms: 1")
    assert any(line.endswith("<- stepping") and " 9 " in line for line in out)
    late = [line for line in out if line.startswith("window at sim")]
    assert len(late) == 1 and "latest wake-up 42.0 ms" in late[0] and "run-queue wait 40.0 ms" in late[0]
    # samples at 149.0, 149.5 and 150.0 s fall in [end - 1.1 s, end + 0.05 s]: two intervals; CPU 0 has the main thread
    # (5 ms per interval), CPU 1 the other two (1 + 2 ms)
    assert "stepping thread over 1.00 s" in late[0] and late[0].endswith("real-time run per CPU, ms: cpu0 10, cpu1 6")
