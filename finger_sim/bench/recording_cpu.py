"""Recording's CPU at 1 kHz against the node's, counted where it runs; `node_bench --recording-cpu`.

    python -m finger_sim.bench.node_bench --recording-cpu [--at-once] [--pin NODE_CPU WRITER_CPU]
        [--target-duration 10] [--rounds 6] [--domain-id <id>]

finger_node (paper_flexion, 1 kHz, publishing every step, nobody sending commands) runs with recording off
and on, `--rounds` times, each measured for `--target-duration` s after node_bench.WARMUP_S: one after the
other (off, on, then on, off), or with `--at-once` both at the same time, each in its own DDS domain
(`--domain-id` and the next), so that both see the same state of the host; `--pin` puts every node's
threads on one CPU and its log writer process on the other (node_bench.measure_window).

The verdict is the node-level figure: the median of the rounds' differences (the node's threads and its
writer process with recording, less the node's threads without, CPU s per sim s to the ns: `node_cpu`)
over the median recording-off round, with its CONFIDENCE bootstrap interval, the rounds resampled in pairs (scipy.stats.bootstrap):
met when the whole interval is at or below GOAL, not met when it is all above, else not decided. One
after the other on a 2-core KVM guest, the same configuration's CPU scattered between rounds by more than
recording adds (a node process's stepping thread runs at ~0.05 or ~0.15 CPU s per sim s), so no interval
decided; at once (and pinned) its intervals were 1.4 to 6 times narrower (docs/node_performance.md,
2026-11-27). Beside it each run is split:

- every thread of the node process, by its OS name (the node names its own: stepping, executor; the
  recorder's: mcap sender, mcap status), from /proc/<pid>/task/<tid>/schedstat read when each /diagnostics
  window arrives (finger_sim.log.cpu_clocks);
- recording's own CPU, as the node reports it in /diagnostics (McapRecorder.cpu): the stepping thread's
  time inside write_records (sampled), the sender and status threads, the writer process.

Recording's own CPU per sim s over the node's CPU per sim s without recording is given too. Its
denominator is the *least* CPU a recording-off round took: the part of the node that is there in every
round; the rounds above it were inflated by something recording does not cause, and dividing by them
would flatter recording. So the ratio errs high, and so does its numerator (the sampled hand-over counts
what remains of its clock reads). What the split leaves out, recording's indirect cost on the stepping thread
(cold caches after the hand-over), is shown beside it: the stepping thread's CPU outside write_records with
recording on, against the stepping thread with recording off in the same round.

With `--old`, the same rounds run the old checkout's pair right after this one's, and a table compares the two
sides part by part (the sender and status threads apart) with each side's node-level on − off difference; its
last row is the change itself: this side's on − off less the old side's, round by round, with its paired
bootstrap interval (own and indirect together, where the parts alone leave the indirect cost out).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from typing import Any

import numpy as np
import scipy.stats

#: The bootstrap interval of the added fraction: its confidence and resamples (scipy.stats.bootstrap, paired
#: by round, percentile method, a fixed seed so that a report's figures can be recomputed).
CONFIDENCE = 0.95
RESAMPLES = 20_000
SEED = 37

BEGIN = "<!-- RECORDING_CPU begin: written by finger_sim/bench/node_bench.py --recording-cpu -->"
END = "<!-- RECORDING_CPU end -->"
GOAL = 0.20  # recording adds at most this fraction of the node's CPU at 1 kHz (issue's goal)
STEPPING = "stepping"  # the node's stepping thread, by its OS name
RECORDER_THREADS = ("mcap sender", "mcap status")


def _spread(values: Sequence[float], fmt: str = ".4f") -> str:
    """'median (min–max)' of `values`."""
    return f"{statistics.median(values):{fmt}} ({min(values):{fmt}}–{max(values):{fmt}})"


def added_fraction(on: np.ndarray, off: np.ndarray, axis: int = -1) -> np.ndarray:
    """CPU recording adds, as a fraction of the node's without it: the median of the rounds' differences
    (each round's on run less its off run) over the median off run. Vectorized along `axis` (the rounds)."""
    return np.median(on - off, axis=axis) / np.median(off, axis=axis)


def added_cpu(on: np.ndarray, off: np.ndarray, axis: int = -1) -> np.ndarray:
    """CPU recording adds, CPU s per sim s: the median of the rounds' differences (on run less off run)."""
    return np.median(on - off, axis=axis)


def interval(on: Sequence[float], off: Sequence[float], statistic: Callable[..., np.ndarray] = added_fraction
             ) -> tuple[float, float]:
    """The CONFIDENCE bootstrap interval of `statistic(on, off)` (`added_fraction`, `added_cpu`), the rounds
    resampled in pairs (on and off of one round stay together): (low, high)."""
    result = scipy.stats.bootstrap((np.asarray(on), np.asarray(off)), statistic, paired=True, vectorized=True,
                                   confidence_level=CONFIDENCE, n_resamples=RESAMPLES, method="percentile",
                                   random_state=np.random.default_rng(SEED))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def decision(low: float, high: float) -> str:
    """'met' when the whole interval is at or below GOAL, 'not met' when it is all above, else 'not decided'."""
    return "met" if high <= GOAL else "not met" if low > GOAL else "not decided"


def design(at_once: bool, pin: Sequence[int] | None) -> str:
    """How a round's two nodes ran (node_bench --at-once, --pin), in words."""
    when = ("at the same time, each in its own DDS domain (started off first in odd rounds, on first in even)" if at_once
            else "one after the other (off, on, then on, off)")
    where = (f"; every node's threads pinned to CPU {pin[0]}, its log writer process to CPU {pin[1]}" if pin is not None
             else "; placed by the kernel")
    return when + where


def node_cpu(w: Any) -> float:
    """The node's CPU s per sim s in one run (node_bench.Window) to the ns: its threads' schedstat and its log
    writer process (the recorder's count). /proc's utime and stime (`cpu_per_sim_s`) count 10 ms ticks:
    ±0.002 CPU s per sim s in a 10 s run, a fifth of what recording adds."""
    return sum(w.threads.values()) + w.recorder.get("writer", 0.0)


def own_cpu(w: Any) -> float:
    """Recording's own CPU s per sim s in one run (node_bench.Window): caller + threads + writer."""
    return sum(w.recorder.values())


def indirect_cpu(off: Sequence[Any], on: Sequence[Any]) -> list[float]:
    """Each round's indirect cost on the stepping thread, CPU s per sim s: its CPU outside write_records with
    recording on, less its CPU with recording off in the same round."""
    return [w.threads.get(STEPPING, 0.0) - w.recorder.get("caller", 0.0) - o.threads.get(STEPPING, 0.0)
            for o, w in zip(off, on)]


def compared(sides: dict[str, tuple[Sequence[Any], Sequence[Any]]]) -> list[str]:
    """A table of what recording adds, by part, side by side: side → its (off, on) runs, measured in the
    same rounds (node_bench --recording-cpu --old); with two sides, a last row of the first's node-level
    on − off difference less the second's, round by round, with its paired bootstrap interval."""
    lines = ["| side | on − off, the node (interval) | recording's own, in all | stepping thread in write_records | "
             "sender thread | status thread | writer process | indirect on the stepping thread | "
             "own / least recording-off round |", "|---|---|---|---|---|---|---|---|---|"]
    added: dict[str, list[float]] = {}
    for side, (off, on) in sides.items():
        floor = min(node_cpu(w) for w in off)
        added[side] = [node_cpu(w) - node_cpu(o) for o, w in zip(off, on)]
        low, high = interval([node_cpu(w) for w in on], [node_cpu(o) for o in off], added_cpu)
        parts = [_spread([w.recorder.get("caller", 0.0) for w in on]),
                 *(_spread([w.threads.get(name, 0.0) for w in on]) for name in RECORDER_THREADS),
                 _spread([w.recorder.get("writer", 0.0) for w in on]), _spread(indirect_cpu(off, on), "+.4f")]
        ratios = [own_cpu(w) / floor for w in on]
        lines.append(f"| {side} | {statistics.median(added[side]):+.4f} ({low:+.4f} to {high:+.4f}) | "
                     f"{_spread([own_cpu(w) for w in on])} | {' | '.join(parts)} | "
                     f"{_spread([100 * r for r in ratios], '.1f')} % |")
    if len(added) == 2:
        (first, a), (second, b) = added.items()
        low, high = interval(a, b, added_cpu)
        lines.append(f"| {first} − {second}, round by round | {float(added_cpu(np.array(a), np.array(b))):+.4f} "
                     f"({low:+.4f} to {high:+.4f}) | | | | | | | |")
    return lines


def report(off: Sequence[Any], on: Sequence[Any], command: str, duration: float, load: tuple[tuple, tuple],
           old: tuple[Sequence[Any], Sequence[Any]] | None = None, how: str = design(False, None)) -> str:
    """The dated section of docs/node_performance.md for the runs `off` and `on` (node_bench.Window, in
    round order), and `old`'s (off, on) runs beside them if given (the same rounds, another checkout);
    `how`: how each round's nodes ran (`design()`)."""
    rounds = len(off)
    node_off = [node_cpu(w) for w in off]
    own = [own_cpu(w) for w in on]
    node_on = [node_cpu(w) for w in on]
    floor, middle = min(node_off), statistics.median(node_off)
    ratios = [x / floor for x in own]

    def part(name: str) -> list[float]:
        return [w.recorder.get(name, 0.0) for w in on]

    def thread(runs: Sequence[Any], name: str) -> list[float]:
        return [w.threads.get(name, 0.0) for w in runs]

    outside = [t - c for t, c in zip(thread(on, STEPPING), part("caller"))]  # stepping thread outside write_records
    paired = indirect_cpu(off, on)  # each round's on run against its off run
    indirect = statistics.median(paired)
    names = sorted({n for w in (*off, *on) for n in w.threads},
                   key=lambda n: -statistics.median(thread(off, n) + thread(on, n)))

    def ratio_row(label: str, values: Sequence[float]) -> str:
        return f"| {label} | " + " | ".join(f"{v:.4f}" for v in values) + f" | {_spread(values)} |"

    by_round = [
        "| CPU s per sim s | " + " | ".join(f"round {r + 1}" for r in range(rounds)) + " | median (min–max) |",
        "|---|" + "---|" * rounds + "---|",
        ratio_row("node, recording off (its threads)", node_off),
        ratio_row("node, recording on (its threads + writer process)", node_on),
        ratio_row("recording's own: stepping thread in write_records (sampled)", part("caller")),
        ratio_row("recording's own: sender + status threads", part("threads")),
        ratio_row("recording's own: writer process", part("writer")),
        ratio_row("**recording's own, in all**", own),
        ratio_row("stepping thread, recording off", thread(off, STEPPING)),
        ratio_row("stepping thread outside write_records, recording on", outside),
        ratio_row("the same minus the stepping thread with recording off, round by round", paired),
    ]
    per_thread = ["| thread (OS name) | recording off: median (min–max) | recording on: median (min–max) |", "|---|---|---|"]
    per_thread += [f"| {n} | {_spread(thread(off, n))} | {_spread(thread(on, n))} |" for n in names
                   if max(thread(off, n) + thread(on, n)) >= 5e-5]
    fraction = float(added_fraction(np.array(node_on), np.array(node_off)))
    low, high = interval(node_on, node_off)
    cpu_low, cpu_high = interval(node_on, node_off, added_cpu)
    verdict = (f"**{decision(low, high).capitalize()}: recording adds {100 * fraction:+.1f} % to the node's CPU at "
               f"1 kHz (the median of the rounds' on − off differences over the median recording-off round; "
               f"{100 * CONFIDENCE:.0f} % paired bootstrap interval {100 * low:+.1f} to {100 * high:+.1f} %), against "
               f"≤ {100 * GOAL:.0f} %.** The difference itself: {float(added_cpu(np.array(node_on), np.array(node_off))):+.4f} "
               f"CPU s per sim s (interval {cpu_low:+.4f} to {cpu_high:+.4f}, {cpu_high - cpu_low:.4f} wide). "
               f"Recording's own CPU, counted where it runs: {100 * statistics.median(ratios):.1f} % "
               f"(rounds {100 * min(ratios):.1f}–{100 * max(ratios):.1f} %) of the least CPU the node took without "
               f"recording ({floor:.4f} CPU s per sim s), "
               f"{100 * statistics.median(own) / middle:.1f} % of the median recording-off round ({middle:.4f}).")
    return "\n".join([
        BEGIN,
        f"## Recording's own CPU at 1 kHz, counted by thread ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC)",
        "",
        f"Command: `{command}`. finger_node (paper_flexion, 1 kHz, publishing every step, nobody sending) with "
        f"recording off and on, {rounds} rounds, the two nodes of a round {how}; {duration:g} s measured after the "
        "warm-up each; CPU s per sim s "
        "from the node's 1 s /diagnostics windows (its `log_cpu_*` keys: `McapRecorder.cpu`) and each thread's "
        "/proc schedstat (finger_sim.log.cpu_clocks); the node's figure is its threads' sum and its writer process's. "
        f"Load average at start {load[0][0]:.1f}, at end {load[1][0]:.1f} on 2 cores.",
        "",
        verdict,
        f"Recording's indirect cost on the stepping thread (its CPU outside write_records with recording on, less "
        f"its CPU with recording off in the same round; median of the rounds): {indirect:+.4f} CPU s per sim s "
        f"(rounds {min(paired):+.4f} to {max(paired):+.4f}; {100 * indirect / floor:+.1f} % of the least "
        f"recording-off round; own and indirect together {100 * (statistics.median(own) + indirect) / floor:.1f} %), "
        f"against the stepping thread's own spread of {min(thread(off, STEPPING)):.4f}–"
        f"{max(thread(off, STEPPING)):.4f} without recording. How the figures are made: "
        "finger_sim/bench/recording_cpu.py's docstring.",
        "",
        *by_round,
        "",
        *per_thread,
        *(["", "Side by side with the old checkout (`--old`), measured in the same rounds, CPU s per sim s, "
           f"median (min–max); the on − off difference with its {100 * CONFIDENCE:.0f} % paired bootstrap interval:",
           "", *compared({"new": (off, on), "old": old})] if old is not None else []),
        END,
    ])

