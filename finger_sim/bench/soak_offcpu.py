"""Why the stepping thread was off its CPU, from the kernel's scheduler events (perf).

The stall trace (finger_sim.runtime.stall_trace) sees a late wake-up from inside the node: run-queue
wait, gc, or `blocked` (neither). This reads what the kernel recorded for the stepping thread
instead, so it also sees stalls in the middle of a step and names who ended a `blocked` one:

    perf record -a --kernel-callchains -g -e sched:sched_wakeup --filter "pid == $TID" \\
        -e sched:sched_switch --filter "prev_pid == $TID || next_pid == $TID" -o perf.data
    perf script -F comm,tid,time,event,trace,ip,sym -i perf.data > perf.txt
    python -m finger_sim.bench.soak_offcpu --perf perf.txt --tid $TID [--min-ms 5] [--wall-offset S]

For every stretch of at least `--min-ms` it prints one line:
- `asleep`, from the thread's switch-out to its wake-up, with the kernel function it slept in (futex_wait:
  a lock, the GIL or a timed wait; a page fault; ...) and what woke it: its own timer (`hrtimer_wakeup`, in
  the context of whatever ran then) or another thread's `futex_wake` (that thread named, with its process
  id from perf's `comm/tid`: a thread of another process holding a lock in shared memory);
- `runnable`, from its wake-up to its switch-in (the run queue).
Then the count of wake-ups per mechanism and waker. Times are perf's clock (CLOCK_MONOTONIC), plus
`--wall-offset` (time.time() - time.monotonic() of the machine) to match the soak's wall times.
"""

from __future__ import annotations

import argparse
import collections
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

#: One event line of `perf script -F comm,tid,time,event,trace,ip,sym`.
EVENT_LINE = re.compile(r"^\s*(?P<comm>\S.*?)\s+(?P<tid>\d+)\s+(?P<t>\d+\.\d+):\s+(?P<event>sched:\w+):\s+(?P<trace>.*)$")
#: Kernel functions that say how a wake-up came (the first of them in its stack is named).
WAKE_MECHANISMS = ("hrtimer_wakeup", "futex_wake", "wake_up_q", "pipe_write", "ep_poll_callback")
#: Kernel functions of the scheduler itself, skipped when naming where a thread slept.
SCHEDULER_FRAMES = ("__schedule", "schedule", "preempt_schedule", "__traceiter", "perf_")


@dataclass
class Event:
    """One scheduler event: who ran it (comm, tid), when (s, perf clock), which, its fields and kernel stack."""

    comm: str
    tid: int
    t: float
    event: str
    trace: str
    stack: list[str] = field(default_factory=list)

    def field(self, name: str) -> str:
        """The value of `name=` in the event's trace text."""
        match = re.search(rf"\b{name}=(\S+)", self.trace)
        return match[1] if match else ""


def parse(lines: Iterable[str]) -> Iterator[Event]:
    """The events of perf script's text, each with its kernel stack (innermost first)."""
    current: Event | None = None
    for line in lines:
        match = EVENT_LINE.match(line)
        if match:
            if current is not None:
                yield current
            current = Event(match["comm"], int(match["tid"]), float(match["t"]), match["event"], match["trace"])
        elif current is not None and line.strip():
            parts = line.split()
            if len(parts) >= 2:
                current.stack.append(parts[1].split("+", 1)[0])
    if current is not None:
        yield current


def mechanism(wakeup: Event) -> str:
    """How a wake-up came: the first of WAKE_MECHANISMS in its stack (wake_up_q counts as futex_wake)."""
    for frame in wakeup.stack:
        if frame in WAKE_MECHANISMS:
            return "futex_wake" if frame == "wake_up_q" else frame
    return wakeup.stack[2] if len(wakeup.stack) > 2 else "?"


def slept_in(switch: Event) -> str:
    """The innermost kernel function outside the scheduler the thread switched out from."""
    for frame in switch.stack:
        if not frame.startswith(SCHEDULER_FRAMES):
            return frame
    return "?"


@dataclass(frozen=True)
class Stretch:
    """A stretch of the thread off its CPU: `asleep` (switch-out to wake-up) or `runnable` (wake-up to switch-in)."""

    kind: str
    start: float
    end: float
    where: str  # asleep: the kernel function it slept in; runnable: ''
    waker: str  # asleep: `comm/tid`; runnable: ''
    how: str  # asleep: the wake-up's mechanism; runnable: ''

    @property
    def ms(self) -> float:
        return (self.end - self.start) * 1e3


def stretches(events: Iterable[Event], tid: int) -> Iterator[Stretch]:
    """The thread's asleep and runnable stretches, from its switch and wake-up events."""
    out: Event | None = None  # its last switch-out
    woken: Event | None = None  # its wake-up since
    for e in events:
        if e.event == "sched:sched_switch" and e.field("prev_pid") == str(tid):
            out, woken = e, None
        elif e.event == "sched:sched_wakeup" and e.field("pid") == str(tid) and out is not None and woken is None:
            woken = e
            yield Stretch("asleep", out.t, e.t, slept_in(out), f"{e.comm}/{e.tid}", mechanism(e))
        elif e.event == "sched:sched_switch" and e.field("next_pid") == str(tid):
            if woken is not None:
                yield Stretch("runnable", woken.t, e.t, "", "", "")
            elif out is not None and out.field("prev_state") == "R":  # preempted: runnable all along
                yield Stretch("runnable", out.t, e.t, "", "", "")
            out = woken = None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--perf", type=Path, required=True, help="text of perf script -F comm,tid,time,event,trace,ip,sym")
    parser.add_argument("--tid", type=int, required=True, help="the stepping thread's id")
    parser.add_argument("--min-ms", type=float, default=5.0, help="list the stretches at least this long")
    parser.add_argument("--wall-offset", type=float, default=0.0, help="added to perf's times: time.time() - time.monotonic(), s")
    args = parser.parse_args(argv)
    wakers: collections.Counter[tuple[str, str]] = collections.Counter()
    with args.perf.open(errors="replace") as lines:
        for s in stretches(parse(lines), args.tid):
            if s.kind == "asleep":
                wakers[(s.how, s.waker if s.how != "hrtimer_wakeup" else "(its timer)")] += 1
            if s.ms >= args.min_ms:
                tail = f" in {s.where}, woken by {s.waker} via {s.how}" if s.kind == "asleep" else ""
                print(f"{s.kind} {s.ms:.1f} ms from {s.start + args.wall_offset:.3f}{tail}")
    print("wake-ups by mechanism and waker: " + "; ".join(f"{how} {who}: {n}" for (how, who), n in wakers.most_common()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
