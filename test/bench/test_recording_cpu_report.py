"""node_bench --recording-cpu's report: the ratio, its spread and the per-thread rows are those of its runs
(computed here with numpy from the same figures); threads are grouped by OS name as documented."""

from __future__ import annotations

import itertools

import numpy as np

from finger_sim.bench import recording_cpu
from finger_sim.bench.node_bench import Window, _per_thread_name

OFF = [0.081, 0.067, 0.057, 0.068, 0.075, 0.066]  # node process, recording off, CPU s per sim s
STEP_OFF = [0.079, 0.065, 0.055, 0.068, 0.074, 0.065]
ON = [0.103, 0.077, 0.095, 0.083, 0.095, 0.084]
STEP_ON = [0.095, 0.070, 0.089, 0.076, 0.087, 0.078]
CALLER = [0.0072, 0.0052, 0.0064, 0.0038, 0.0053, 0.0037]
THREADS, WRITER = 0.0021, 0.0036


# the node's CPU to the ns: the sum of its threads (and its writer process with recording on)
NODE_OFF = np.array(STEP_OFF) + 0.0007
NODE_ON = np.array(STEP_ON) + 0.0007 + 0.0019 + WRITER


def _off() -> list[Window]:
    return [Window(cpu_per_sim_s=c, threads={"stepping": s, "executor": 0.0007}) for c, s in zip(OFF, STEP_OFF)]


def _on() -> list[Window]:
    return [Window(cpu_per_sim_s=c, threads={"stepping": s, "executor": 0.0007, "mcap sender": 0.0019},
                   recorder={"caller": k, "threads": THREADS, "writer": WRITER}) for c, s, k in zip(ON, STEP_ON, CALLER)]


def _cells(section: str, label: str) -> list[str]:
    (line,) = [line for line in section.splitlines() if line.startswith(f"| {label} |")]
    return [cell.strip() for cell in line.strip("|").split("|")]


def _exact_bootstrap(on: np.ndarray, off: np.ndarray) -> np.ndarray:
    """added_fraction of every one of the n**n equally likely paired resamples of n rounds (numpy, by enumeration)."""
    n = len(on)
    picks = np.array(list(itertools.product(range(n), repeat=n)))
    return np.median(on[picks] - off[picks], axis=1) / np.median(off[picks], axis=1)


def test_interval_is_the_paired_bootstrap_of_the_added_fraction() -> None:
    # the off runs scatter (a node's CPU does), the paired differences hardly: only a paired resampling is narrow
    off = np.array([0.095, 0.150, 0.102, 0.121, 0.110])
    on = off + np.array([0.0105, 0.0098, 0.0112, 0.0101, 0.0107])
    exact = _exact_bootstrap(on, off)
    low, high = recording_cpu.interval(on, off)
    assert np.quantile(exact, 0.010) <= low <= np.quantile(exact, 0.040)
    assert np.quantile(exact, 0.960) <= high <= np.quantile(exact, 0.990)
    assert recording_cpu.decision(low, high) == "met"
    assert recording_cpu.decision(0.15, 0.25) == "not decided" and recording_cpu.decision(0.21, 0.3) == "not met"


def test_ratio_to_the_least_recording_off_round_with_its_spread() -> None:
    section = recording_cpu.report(_off(), _on(), "cmd", 10.0, ((1.4,), (2.2,)))
    own = np.array(CALLER) + THREADS + WRITER
    ratios = own / NODE_OFF.min()
    assert (f"Recording's own CPU, counted where it runs: {100 * np.median(ratios):.1f} % (rounds {100 * ratios.min():.1f}–"
            f"{100 * ratios.max():.1f} %) of the least CPU the node took without recording ({NODE_OFF.min():.4f}") in section
    diffs = NODE_ON - NODE_OFF
    fraction = np.median(diffs) / np.median(NODE_OFF)
    low, high = recording_cpu.interval(NODE_ON, NODE_OFF)
    verdict = "Met" if high <= 0.20 else "Not met" if low > 0.20 else "Not decided"
    assert (f"**{verdict}: recording adds {100 * fraction:+.1f} % to the node's CPU at 1 kHz (the median of the rounds' "
            f"on − off differences over the median recording-off round; 95 % paired bootstrap interval {100 * low:+.1f} "
            f"to {100 * high:+.1f} %), against ≤ 20 %.** The difference itself: {np.median(diffs):+.4f}") in section
    assert f"{100 * np.median(own) / np.median(NODE_OFF):.1f} % of the median recording-off round" in section
    assert _cells(section, "node, recording on (its threads + writer process)")[1:7] == [f"{x:.4f}" for x in NODE_ON]
    assert _cells(section, "**recording's own, in all**")[1:7] == [f"{x:.4f}" for x in own]
    outside = np.array(STEP_ON) - np.array(CALLER)
    assert _cells(section, "stepping thread outside write_records, recording on")[1:7] == [f"{x:.4f}" for x in outside]
    paired = outside - np.array(STEP_OFF)
    indirect = np.median(paired)
    assert (f"median of the rounds): {indirect:+.4f} CPU s per sim s (rounds {paired.min():+.4f} to {paired.max():+.4f}; "
            f"{100 * indirect / NODE_OFF.min():+.1f} % of the least recording-off round; own and indirect together "
            f"{100 * (np.median(own) + indirect) / NODE_OFF.min():.1f} %)") in section
    stepping = _cells(section, "stepping")
    assert stepping[1] == f"{np.median(STEP_OFF):.4f} ({min(STEP_OFF):.4f}–{max(STEP_OFF):.4f})"
    assert _cells(section, "mcap sender")[1:] == ["0.0000 (0.0000–0.0000)", "0.0019 (0.0019–0.0019)"]
    assert section.startswith(recording_cpu.BEGIN) and section.endswith(recording_cpu.END)


def test_threads_grouped_by_name_without_their_number() -> None:
    before = {1: ("stepping", 0), 2: ("dds.shm.7000", 1_000_000), 3: ("dds.shm.23661", 0), 4: ("gone", 5)}
    after = {1: ("stepping", 50_000_000), 2: ("dds.shm.7000", 3_000_000), 3: ("dds.shm.23661", 1_000_000),
             5: ("new", 9_000_000)}
    assert _per_thread_name(before, after, 2.0) == {"stepping": 0.025, "dds.shm.#": 0.0015}


def test_old_side_by_side_table() -> None:
    old_step_on = np.array(STEP_ON) + 0.002
    old_on = [Window(cpu_per_sim_s=c, threads={"stepping": s, "executor": 0.0007, "mcap sender": 0.0017,
                                               "mcap status": 0.0002},
                     recorder={"caller": k + 0.001, "threads": THREADS, "writer": WRITER})
              for c, s, k in zip(ON, old_step_on, CALLER)]
    section = recording_cpu.report(_off(), _on(), "cmd", 10.0, ((1.0,), (1.0,)), old=(_off(), old_on))
    old_own = np.array(CALLER) + 0.001 + THREADS + WRITER
    cells = _cells(section, "old")
    old_added = (old_step_on + 0.0007 + 0.0019 + WRITER) - NODE_OFF  # its threads and writer, less the off run
    low, high = recording_cpu.interval(old_added + NODE_OFF, NODE_OFF, recording_cpu.added_cpu)
    assert cells[1] == f"{np.median(old_added):+.4f} ({low:+.4f} to {high:+.4f})"
    assert cells[2] == f"{np.median(old_own):.4f} ({old_own.min():.4f}–{old_own.max():.4f})"
    caller = np.array(CALLER) + 0.001
    assert cells[3] == f"{np.median(caller):.4f} ({caller.min():.4f}–{caller.max():.4f})"
    assert cells[4:6] == ["0.0017 (0.0017–0.0017)", "0.0002 (0.0002–0.0002)"]
    indirect = old_step_on - caller - np.array(STEP_OFF)
    assert cells[7] == f"{np.median(indirect):+.4f} ({indirect.min():+.4f}–{indirect.max():+.4f})"
    ratios = 100 * old_own / NODE_OFF.min()
    assert cells[8] == f"{np.median(ratios):.1f} ({ratios.min():.1f}–{ratios.max():.1f}) %"
    # the change itself: new's on − off less old's, round by round (old's stepping thread took 0.002 more)
    change = (NODE_ON - NODE_OFF) - old_added
    low, high = recording_cpu.interval(NODE_ON - NODE_OFF, old_added, recording_cpu.added_cpu)
    assert _cells(section, "new − old, round by round")[1] == f"{np.median(change):+.4f} ({low:+.4f} to {high:+.4f})"
    assert np.isclose(np.median(change), -0.002)
    assert "| new |" in section and "| old |" not in recording_cpu.report(_off(), _on(), "cmd", 10.0, ((1.0,), (1.0,)))
