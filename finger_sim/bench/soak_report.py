"""Summary of a soak: late wake-ups per /diagnostics window and what each thread did meanwhile.

Reads test/ros/test_soak.py's soak_windows.csv (the node's 1 s windows: real-time factor, latest
wake-up, received at wall time) and finger_sim.bench.soak_probe's CSV (every thread of the test's
process tree, sampled), and prints:
- the windows after the warm-up: how many fell below the real-time rule, and the distribution
  of each window's latest wake-up (a window below 0.99 needs a wake-up at least 10 ms late);
- per thread: policy, priority, CPU time, run-queue wait and page faults over the soak;
- the process tree's CPU time per policy, in cores (the real-time part is what the kernel's
  real-time throttling budgets: kernel.sched_rt_runtime_us of each CPU's second);
- for each window with a wake-up later than `--late-ms`: the stepping thread's run-queue wait,
  major faults and forced switches around it, the machine's steal, and the real-time threads'
  run time per CPU in the second before (a CPU near kernel.sched_rt_runtime_us of real-time
  run time gets throttled);
- with `--trace DIR` (the node's FINGER_SIM_STALL_TRACE directory, finger_sim.runtime.stall_trace):
  the garbage collections per generation, and every wake-up at least `--late-ms` late with its
  cause: `gc` (a collection covered at least half of it), `run queue` (the thread was runnable
  but not run for at least half of it) or `blocked` (neither: the GIL or another lock held by
  another thread, or a late timer), with where the other Python threads were.

    python -m finger_sim.bench.soak_report --windows .../soak_windows.csv --probe probe.csv [--late-ms 10] [--trace DIR]
"""

from __future__ import annotations

import argparse
import collections
import csv
from pathlib import Path

#: Wall s after the first window that the soak test does not judge (test_soak.WARMUP_S).
WARMUP_S = 60.0
#: The test's real-time rule (test_soak.MIN_WINDOW_RTF).
MIN_WINDOW_RTF = 0.99
#: The node's module name in the probe's `proc` column.
NODE = "finger_sim.ros.node"
REALTIME = {"1", "2"}  # SCHED_FIFO, SCHED_RR
#: Share of a late wake-up a cause must cover to be named as the cause.
CAUSE_SHARE = 0.5
#: Run-queue wait (ms) over a stall from which a thread is listed as stopped with it.
STOPPED_WAIT_MS = 20.0


def cause(stall: dict[str, str]) -> str:
    """The cause of one stall_trace row: gc, run queue or blocked (see the module doc)."""
    late = float(stall["late_ms"])
    if float(stall["gc_ms"]) >= CAUSE_SHARE * late:
        return "gc"
    if float(stall["runqueue_ms"]) >= CAUSE_SHARE * late:
        return "run queue"
    return "blocked"


def stopped_with(threads: dict[tuple[str, int], list[dict[str, str]]], start: float, end: float) -> str:
    """The threads whose run-queue wait grew by at least STOPPED_WAIT_MS between the probe's samples
    around wall s `start`..`end` (a throttled CPU stops all its real-time threads at once; a thread
    stopped while holding the GIL blocks the stepping thread), as `name/tid +wait ms`, `; `-separated."""
    out = []
    for (proc, tid), rows in threads.items():
        before = [r for r in rows if float(r["wall_s"]) <= start]
        after = [r for r in rows if float(r["wall_s"]) >= end]
        if before and after:
            waited = (int(after[0]["wait_ns"]) - int(before[-1]["wait_ns"])) / 1e6
            if waited >= STOPPED_WAIT_MS:
                out.append(f"{proc.rsplit('.', 1)[-1]}:{after[0]['thread']}/{tid} +{waited:.0f} ms")
    return "; ".join(out) or "none"


def report_trace(directory: Path, late_ms: float, t_judged: float,
                 threads: dict[tuple[str, int], list[dict[str, str]]]) -> None:
    """Print the collections and the stalls of a stall_trace directory (wake-ups from wall `t_judged` on),
    each stall with the threads of the probe stopped in the run queue over it."""
    collections_by_gen: dict[str, list[float]] = collections.defaultdict(list)
    for path in sorted(directory.glob("gc_*.csv")):
        for row in csv.DictReader(path.open()):
            if float(row["wall_s"]) >= t_judged:
                collections_by_gen[row["generation"]].append(float(row["duration_ms"]))
    print("garbage collections written (gen 0 only when >= 0.5 ms): " + "; ".join(
        f"gen {g}: {len(d)}, max {max(d):.2f} ms, total {sum(d):.0f} ms" for g, d in sorted(collections_by_gen.items())))
    stalls = [row for path in sorted(directory.glob("stalls_*.csv")) for row in csv.DictReader(path.open())
              if float(row["wall_s"]) >= t_judged and float(row["late_ms"]) >= late_ms]
    print(f"wake-ups >= {late_ms:g} ms late: {len(stalls)}; by cause: " + ", ".join(
        f"{c} {n}" for c, n in sorted(collections.Counter(cause(s) for s in stalls).items())))
    for s in stalls:
        print(f"stall at wall {float(s['wall_s']):.3f}: {float(s['late_ms']):.1f} ms late, cause {cause(s)}: "
              f"run-queue {float(s['runqueue_ms']):.1f} ms, gc {float(s['gc_ms']):.1f} ms, ran {float(s['run_ms']):.1f} ms; "
              f"others {s['others']}; stopped in the run queue over it: "
              f"{stopped_with(threads, float(s['wall_s']) - float(s['late_ms']) / 1e3, float(s['wall_s']))}")


def print_cores_per_policy(threads: dict[tuple[str, int], list[dict[str, str]]]) -> None:
    """Print the CPU time of the probed threads over the probe's wall span, in cores, real-time
    (SCHED_FIFO/RR at the last sample) and normal, each with its number of threads."""
    span = (max(float(rows[-1]["wall_s"]) for rows in threads.values())
            - min(float(rows[0]["wall_s"]) for rows in threads.values()))
    cpu_s: dict[str, float] = collections.defaultdict(float)
    count: collections.Counter[str] = collections.Counter()
    for rows in threads.values():
        kind = "real-time" if rows[-1]["policy"] in REALTIME else "normal"
        cpu_s[kind] += (int(rows[-1]["run_ns"]) - int(rows[0]["run_ns"])) / 1e9
        count[kind] += 1
    print(f"CPU over the probe's {span:.1f} s, cores: " + ", ".join(
        f"{kind} {cpu_s[kind] / span:.3f} ({count[kind]} threads)" for kind in ("real-time", "normal")))


def _percentile(sorted_values: list[float], p: float) -> float:
    return sorted_values[min(int(p / 100 * len(sorted_values)), len(sorted_values) - 1)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--windows", type=Path, required=True)
    parser.add_argument("--probe", type=Path, required=True)
    parser.add_argument("--late-ms", type=float, default=10.0, help="list the windows with a wake-up at least this late")
    parser.add_argument("--trace", type=Path, help="the node's FINGER_SIM_STALL_TRACE directory")
    args = parser.parse_args(argv)
    windows = list(csv.DictReader(args.windows.open()))
    t0 = float(windows[0]["wall_s"])
    judged = [w for w in windows if float(w["wall_s"]) - t0 >= WARMUP_S]
    late = sorted(float(w["late_wakeup_max_ms"]) for w in judged)
    rtf = [float(w["window_rtf"]) for w in judged]
    print(f"{len(judged)} windows after {WARMUP_S:g} s: {sum(r < MIN_WINDOW_RTF for r in rtf)} below {MIN_WINDOW_RTF}, "
          f"lowest {min(rtf):.4f}; steps dropped {windows[-1]['dropped_steps']}")
    print("latest wake-up per window, ms: median {:.2f}, p90 {:.2f}, p99 {:.2f}, max {:.2f}; windows with one >= 5 ms: {}, "
          ">= 10 ms: {}, >= 20 ms: {}".format(_percentile(late, 50), _percentile(late, 90), _percentile(late, 99), late[-1],
                                             sum(x >= 5 for x in late), sum(x >= 10 for x in late), sum(x >= 20 for x in late)))
    threads: dict[tuple[str, int], list[dict[str, str]]] = collections.defaultdict(list)
    for row in csv.DictReader(args.probe.open()):
        threads[(row["proc"], int(row["tid"]))].append(row)
    node = [k for k in threads if k[0] == NODE and k[1] != int(threads[k][-1]["pid"])  # not the main (executor) thread
            and not threads[k][-1]["thread"].startswith("dds.")]  # nor the middleware's
    stepping = max(node, key=lambda k: int(threads[k][-1]["vol_switches"]))  # it sleeps once per step
    print("thread (process/tid/name)                      policy prio   CPU s  wait s majflt")
    for key, rows in sorted(threads.items(), key=lambda kv: -int(kv[1][-1]["run_ns"]))[:16]:
        first, last = rows[0], rows[-1]
        mark = " <- stepping" if key == stepping else ""
        print(f"{key[0].rsplit('.', 1)[-1][:18]:18s} {key[1]:8d} {last['thread'][:16]:16s} {last['policy']:>6s} {last['rtprio']:>4s} "
              f"{(int(last['run_ns']) - int(first['run_ns'])) / 1e9:7.2f} {(int(last['wait_ns']) - int(first['wait_ns'])) / 1e9:7.2f} "
              f"{int(last['majflt']) - int(first['majflt']):6d}{mark}")
    print_cores_per_policy(threads)
    for w in [w for w in judged if float(w["late_wakeup_max_ms"]) >= args.late_ms]:
        end = float(w["wall_s"])
        rows = [r for r in threads[stepping] if end - 1.1 <= float(r["wall_s"]) <= end + 0.05]
        if len(rows) < 2:
            continue
        a, b = rows[0], rows[-1]
        per_cpu: dict[str, float] = collections.defaultdict(float)
        for key, series in threads.items():
            inside = [r for r in series if end - 1.1 <= float(r["wall_s"]) <= end + 0.05 and r["policy"] in REALTIME]
            for r0, r1 in zip(inside, inside[1:]):
                per_cpu[r1.get("cpu", "?")] += (int(r1["run_ns"]) - int(r0["run_ns"])) / 1e6
        span = float(b["wall_s"]) - float(a["wall_s"])
        print(f"window at sim {float(w['sim_t_s']):7.1f} s: RTF {w['window_rtf']}, latest wake-up {float(w['late_wakeup_max_ms']):.1f} ms; "
              f"stepping thread over {span:.2f} s: run-queue wait {(int(b['wait_ns']) - int(a['wait_ns'])) / 1e6:.1f} ms, "
              f"forced switches {int(b['forced_switches']) - int(a['forced_switches'])}, major faults {int(b['majflt']) - int(a['majflt'])}; "
              f"steal {float(b['steal_s']) - float(a['steal_s']):.2f} s; real-time run per CPU, ms: "
              + ", ".join(f"cpu{c} {ms:.0f}" for c, ms in sorted(per_cpu.items())))
    if args.trace is not None:
        report_trace(args.trace, args.late_ms, t0 + WARMUP_S, threads)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
