"""Resim speed including reading, before and after the fast log path, in one process.

    python -m finger_sim.bench.resim_read_bench LOG.mcap [LOG.mcap ...] [--repeats 5]

For each node log: the median over `--repeats` runs of
- before: every record of the file scanned and every chunk decompressed (mcap's stream
  reader), joint states and command-log entries decoded by rosbags (the reading of
  `load_run` before the chunk-skipping reader and the fixed-layout CDR readers);
- after: `load_run(read_log(log))` as it is (chunks holding no wanted topic skipped, only
  the wanted records parsed, fixed-layout CDR);
- resim: `resimulate(run)` (the same in both);
and the real-time factors sim s / (read + resim) wall s. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from finger_sim.log import read_log
from finger_sim.log.reader import ROSBAGS
from finger_sim.run_log import CommandEvent, RecordedRun, RunMetadata, _joint_order, _states_topic, load_run, resimulate


def _load_before(path: Path) -> RecordedRun:
    """load_run's reading as it was: a full scan of the file and rosbags for every message."""
    reader = read_log(path)
    reader._chunk_indexes = []  # noqa: SLF001 - the bench measures the scan path on purpose
    run = RecordedRun(metadata=RunMetadata.from_dict(reader.metadata_record("finger_sim"), path))
    states = _states_topic(reader)
    logs = [t for t in reader.topics if t.endswith("/command_log")]
    order = None
    for msg in reader.messages([states, *logs], decoder=ROSBAGS):
        if msg.topic != states:
            run.events.append(CommandEvent.from_values({kv.key: kv.value for kv in msg.msg.values}, path))
            continue
        js = msg.msg
        order = order or _joint_order(reader, list(js.name))
        stamp = js.header.stamp.sec * 1_000_000_000 + js.header.stamp.nanosec
        run.joint_states.append((stamp, tuple(float(js.position[i]) for i in order)
                                 + tuple(float(js.velocity[i]) for i in order)))  # type: ignore[arg-type]
    return run


def _median_s(work, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = work()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="resim_read_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", type=Path, nargs="+")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    print("| log | sim s | states | events | read before | read after | resim | RTF before | RTF after |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in args.logs:
        resimulate(load_run(read_log(path)))  # warm-up: imports, kernel loading
        before_s, old = _median_s(lambda: _load_before(path), args.repeats)
        after_s, run = _median_s(lambda: load_run(read_log(path)), args.repeats)
        assert old.joint_states == run.joint_states and old.events == run.events, "the readers disagree"  # type: ignore[union-attr]
        resim_s, result = _median_s(lambda: resimulate(run), args.repeats)
        assert result.exact, result.summary()  # type: ignore[union-attr]
        sim_s = (run.joint_states[-1][0] - run.joint_states[0][0]) / 1e9
        n = len(run.joint_states)
        print(f"| {path.name} | {sim_s:.2f} | {n} | {len(run.events)} | {before_s * 1e3:.0f} ms ({before_s / n * 1e6:.1f} µs/state) "
              f"| {after_s * 1e3:.0f} ms ({after_s / n * 1e6:.1f} µs/state) | {resim_s * 1e3:.0f} ms "
              f"| {sim_s / (before_s + resim_s):.0f}× | {sim_s / (after_s + resim_s):.0f}× |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
