"""node_bench --recording's report: the medians, spreads and paired differences it prints are those of
its runs (computed here with numpy from the same figures); the hand's rows appear only when it ran.
--targets' report: its medians and verdicts, the recording row left to --recording-cpu."""

from __future__ import annotations

import numpy as np

from pathlib import Path

from finger_sim.bench.node_bench import Window, recording_report, targets_report

OFF = [0.067, 0.072, 0.073, 0.062, 0.066, 0.043, 0.059, 0.059]
ON = [0.080, 0.086, 0.082, 0.072, 0.080, 0.079, 0.075, 0.074]
WRITER = [0.003, 0.003, 0.005, 0.004, 0.004, 0.005, 0.004, 0.003]


def _runs(cpu: list[float], writer: list[float] | None = None) -> list[Window]:
    return [Window(cpu_per_sim_s=c, writer_per_sim_s=w, rtf=[1.0]) for c, w in zip(cpu, writer or [0.0] * len(cpu))]


def _row(section: str, label: str) -> list[str]:
    (line,) = [line for line in section.splitlines() if line.startswith(f"| new | {label}")]
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_recording_report_medians_spreads_and_paired_differences() -> None:
    runs = {("1k_off", "new"): _runs(OFF), ("1k_rec", "new"): _runs(ON, WRITER)}
    section = recording_report(runs, "cmd", None, 10.0, len(OFF), ((8.0,), (3.0,)))
    off, on, diff = np.array(OFF), np.array(ON), np.array(ON) - np.array(OFF)
    assert _row(section, "finger_node 1 kHz, recording off")[3:5] == [f"{np.median(off):.3f}",
                                                                     f"{off.min():.3f}–{off.max():.3f}"]
    assert _row(section, "finger_node 1 kHz, recording on")[3:5] == [f"{np.median(on):.3f}", f"{on.min():.3f}–{on.max():.3f}"]
    paired = _row(section, "  on − off")
    assert paired[2] == ", ".join(f"{d:+.3f}" for d in diff)
    assert paired[3:5] == [f"{np.median(diff):+.3f}", f"{diff.min():+.3f} to {diff.max():+.3f}"]
    added = _row(section, "**CPU added by recording")
    ratio, by_rounds = np.median(on) / np.median(off) - 1, np.median(diff) / np.median(off)
    assert added[3] == f"{100 * ratio:+.0f} %; {100 * by_rounds:+.0f} %"
    assert added[6] == ("yes" if ratio <= 0.2 else "**no**")
    assert "finger_hand" not in section


def test_recording_report_has_the_hand_when_it_ran() -> None:
    runs = {(name, "new"): _runs([c] * 3) for name, c in
            (("1k_off", 0.05), ("1k_rec", 0.06), ("hand10_off", 0.15), ("hand10_rec", 0.18))}
    section = recording_report(runs, "cmd", None, 10.0, 3, ((1.0,), (1.0,)))
    assert _row(section, "**10-finger finger_hand 1 kHz, recording on**")[3:7] == ["0.180", "0.180–0.180", "≤ 0.35", "yes"]
    assert _row(section, "  CPU added by recording, hand")[3] == f"{100 * (0.18 / 0.15 - 1):+.0f} %"


def _target_row(section: str, label: str) -> list[str]:
    (line,) = [line for line in section.splitlines() if line.startswith(f"| {label} |")]
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_targets_report_medians_and_verdicts_leave_recording_to_recording_cpu() -> None:
    """Three rounds a side; the fast run's log complete, the hand above its 0.35 cores on the old side."""
    cpu = {"1k_off": (0.050, 0.060), "1k_rec": (0.058, 0.055), "fast_rec": (0.015, 0.016), "5k_rec": (0.17, 0.16),
           "hand10_rec": (0.20, 0.40)}
    rtf = {"1k_off": 1.0, "1k_rec": 1.0, "fast_rec": 70.0, "5k_rec": 1.0, "hand10_rec": 1.0}
    runs = {(name, side): [Window(cores=c, cpu_per_sim_s=c * k, rtf=[rtf[name]] * 3, log_dropped=0, states_logged=900,
                                  states_expected=900) for k in (0.9, 1.0, 1.1)]
            for name, pair in cpu.items() for side, c in zip(("new", "old"), pair)}
    section = targets_report(runs, "cmd", Path("/old"), 10.0, 3, ((0.1,), (0.2,)))
    added = _target_row(section, "CPU added by recording at 1 kHz")
    assert added[1:4] == [f"{100 * (0.058 / 0.050 - 1):+.0f} %", f"{100 * (0.055 / 0.060 - 1):+.0f} %", "≤ 20 %"]
    assert added[4] == "not decided here: `--recording-cpu`"  # sequential rounds cannot resolve it
    assert _target_row(section, "as fast as possible, publishing and recording every step: sim s per wall s "
                                "(median window)")[1:5] == ["70.0×", "70.0×", "≥ 30×", "yes"]
    hand = _target_row(section, "10-finger finger_hand at 1 kHz, recording: CPU s per sim s (cores at real time)")
    assert hand[1:5] == ["0.200", "0.400", "≤ 0.35", "yes"]
