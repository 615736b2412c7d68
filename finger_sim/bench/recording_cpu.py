"""Recording's own CPU at 1 kHz against the node's, counted where it runs; `node_bench --recording-cpu`.

    python -m finger_sim.bench.node_bench --recording-cpu [--target-duration 10] [--rounds 6] [--domain-id <id>]

finger_node (paper_flexion, 1 kHz, publishing every step, nobody sending commands) runs with recording off,
then on, `--rounds` times (A B A B), each measured for `--target-duration` s after node_bench.WARMUP_S. A
node-level difference (on − off) cannot decide the goal (≤ 20 %): the same configuration's CPU scatters
between rounds by more than recording adds. So each run is split instead:

- every thread of the node process, by its OS name (the node names its own: stepping, executor; the
  recorder's: mcap sender, mcap status), from /proc/<pid>/task/<tid>/schedstat read when each /diagnostics
  window arrives (finger_sim.log.cpu_clocks);
- recording's own CPU, as the node reports it in /diagnostics (McapRecorder.cpu): the stepping thread's
  time inside write_records (sampled), the sender and status threads, the writer process.

The figure: recording's own CPU per sim s over the node's CPU per sim s without recording. Its
denominator is the *least* CPU a recording-off round took: the part of the node that is there in every
round; the rounds above it were inflated by something recording does not cause, and dividing by them
would flatter recording. So the ratio errs high, and so does its numerator (the sampled hand-over counts
what remains of its clock reads). What it leaves out, recording's indirect cost on the stepping thread
(cold caches after the hand-over), is shown beside it: the stepping thread's CPU outside write_records with
recording on, against the stepping thread with recording off in the same round. The rounds run off, on,
then on, off (node_bench), so that a drift of the machine's load falls on both alike.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from datetime import datetime, timezone
from typing import Any

BEGIN = "<!-- RECORDING_CPU begin: written by finger_sim/bench/node_bench.py --recording-cpu -->"
END = "<!-- RECORDING_CPU end -->"
GOAL = 0.20  # recording adds at most this fraction of the node's CPU at 1 kHz (issue's goal)
STEPPING = "stepping"  # the node's stepping thread, by its OS name
RECORDER_THREADS = ("mcap sender", "mcap status")


def _spread(values: Sequence[float], fmt: str = ".4f") -> str:
    """'median (min–max)' of `values`."""
    return f"{statistics.median(values):{fmt}} ({min(values):{fmt}}–{max(values):{fmt}})"


def own_cpu(w: Any) -> float:
    """Recording's own CPU s per sim s in one run (node_bench.Window): caller + threads + writer."""
    return sum(w.recorder.values())


def compared(sides: dict[str, tuple[Sequence[Any], Sequence[Any]]]) -> list[str]:
    """A table of recording's own CPU by part, side by side: side → its (off, on) runs, measured in the
    same rounds (node_bench --recording-cpu --old)."""
    lines = ["| side | recording's own, in all | stepping thread in write_records | sender + status threads | "
             "writer process | own / least recording-off round |", "|---|---|---|---|---|---|"]
    for side, (off, on) in sides.items():
        floor = min(w.cpu_per_sim_s for w in off)
        parts = [_spread([w.recorder.get(k, 0.0) for w in on]) for k in ("caller", "threads", "writer")]
        ratios = [own_cpu(w) / floor for w in on]
        lines.append(f"| {side} | {_spread([own_cpu(w) for w in on])} | {' | '.join(parts)} | "
                     f"{_spread([100 * r for r in ratios], '.1f')} % |")
    return lines


def report(off: Sequence[Any], on: Sequence[Any], command: str, duration: float, load: tuple[tuple, tuple],
           old: tuple[Sequence[Any], Sequence[Any]] | None = None) -> str:
    """The dated section of docs/node_performance.md for the runs `off` and `on` (node_bench.Window, in
    round order), and `old`'s (off, on) runs beside them if given (the same rounds, another checkout)."""
    rounds = len(off)
    node_off = [w.cpu_per_sim_s for w in off]
    own = [own_cpu(w) for w in on]
    floor, middle = min(node_off), statistics.median(node_off)
    ratios = [x / floor for x in own]

    def part(name: str) -> list[float]:
        return [w.recorder.get(name, 0.0) for w in on]

    def thread(runs: Sequence[Any], name: str) -> list[float]:
        return [w.threads.get(name, 0.0) for w in runs]

    outside = [t - c for t, c in zip(thread(on, STEPPING), part("caller"))]  # stepping thread outside write_records
    paired = [o - f for o, f in zip(outside, thread(off, STEPPING))]  # each round's on run against its off run
    indirect = statistics.median(paired)
    names = sorted({n for w in (*off, *on) for n in w.threads},
                   key=lambda n: -statistics.median(thread(off, n) + thread(on, n)))

    def ratio_row(label: str, values: Sequence[float]) -> str:
        return f"| {label} | " + " | ".join(f"{v:.4f}" for v in values) + f" | {_spread(values)} |"

    by_round = [
        "| CPU s per sim s | " + " | ".join(f"round {r + 1}" for r in range(rounds)) + " | median (min–max) |",
        "|---|" + "---|" * rounds + "---|",
        ratio_row("node, recording off (process)", node_off),
        ratio_row("node, recording on (process + writer process)", [w.cpu_per_sim_s for w in on]),
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
    met = statistics.median(ratios) <= GOAL
    verdict = (f"**{'Met' if met else 'Not met'}: recording's own CPU is {100 * statistics.median(ratios):.1f} % "
               f"(rounds {100 * min(ratios):.1f}–{100 * max(ratios):.1f} %) of the least CPU the node took without "
               f"recording ({floor:.4f} CPU s per sim s), against ≤ {100 * GOAL:.0f} %**; "
               f"{100 * statistics.median(own) / middle:.1f} % of the median recording-off round ({middle:.4f}).")
    return "\n".join([
        BEGIN,
        f"## Recording's own CPU at 1 kHz, counted by thread ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC)",
        "",
        f"Command: `{command}`. finger_node (paper_flexion, 1 kHz, publishing every step, nobody sending) with "
        f"recording off and on, {rounds} rounds (off, on, then on, off), {duration:g} s measured after the warm-up "
        "each; CPU s per sim s "
        "from the node's 1 s /diagnostics windows (its `log_cpu_*` keys: `McapRecorder.cpu`) and each thread's "
        "/proc schedstat (finger_sim.log.cpu_clocks). "
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
           "median (min–max):", "", *compared({"new": (off, on), "old": old})] if old is not None else []),
        END,
    ])

