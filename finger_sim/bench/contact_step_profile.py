"""Where a contact step's time goes, step by step: `python -m finger_sim.bench.contact_step_profile [--runs N]`.

`method: auto` at 1 kHz through `Simulator.step` (the node's path) on contact scenes. Every step of
a whole run is timed (`time.perf_counter`) and sorted by who took it (the kernel counts the steps it
takes):

- *kernel*: the common step, one compiled call (`simulation.event_step`); its compiled call is timed
  on its own in every other run (the timer's Python kept out of the step times), so (a) the Python
  around it and (b) the kernel's time are apart;
- *event*: a step with a located crossing: taken whole by the kernel (a contact onset or release located
  and stepped past in the same call, `EventStep.settled`), or by Python (a possible crossing handed over
  by the kernel, or one the kernel declines: the location, an impact's velocity jump and restart, the
  hand-over); its kernel call timed apart;
- *first*: the run's first step (DOP853's initial step size).

(c) The method: accepted DOP853 internal steps per 1 ms output in the kernel's steps (the kernel's
log; rejected attempts not counted), each 15 right-hand sides (12 stages, the last the next step's
first, and 3 more for the dense output), against rk6's 7 per output; and the kernel step's cost on
the same scene before the first event (the same method, no contact yet).
(d) Event steps: how many per run, the impacts counted by the Simulator; with --attempts, their DOP853
attempts by phase (`event_attempts`: pass 1 up to the kink and past it, the cut, the rest), each costing about
the kernel call with one internal step less the one with none.

Each step's median over the runs (every run takes the same path; the median drops the shared
machine's preemptions), summed by kind; one Simulator per scene, reset between runs, after two
warm-up runs (one with the timer, one without). The free step is paper_flexion under `auto` (rk6's lean compiled step), timed the
same way.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence
from typing import Any

from finger_sim.bench import event_attempts
from finger_sim.bench.plan import config_dir
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

#: The scenes profiled (task: the grasp, and the two with impacts).
SCENES = ("grasp_cylinder", "grasp_impact", "grasp_rigid")
FREE_SCENE = "paper_flexion"
#: Whole runs per scene and per timing (median).
RUNS = 25
#: DOP853's right-hand sides per accepted internal step with its dense output, and rk6's per step.
DOP853_RHS, RK6_RHS = 15, 7


class _TimedCall:
    """Wraps an `EventStep`'s compiled entry: the time in it (s) and its last count of internal steps."""

    def __init__(self, events: Any) -> None:
        self.inner, self.events = events._call, events  # noqa: SLF001
        self.seconds, self.internal = 0.0, 0

    def __call__(self, *args: Any) -> Any:
        start = time.perf_counter()
        out = self.inner(*args)
        self.seconds += time.perf_counter() - start
        self.internal = int(self.events._log[self.events._k.internal_steps.COUNT])  # noqa: SLF001
        return out


def profile_scene(name: str, runs: int) -> dict[str, float]:
    """Sums over one run of `name` of each step's median over `runs` runs (µs; robust to the shared machine's
    preemptions, as every run takes the same path), by kind of step, and counts."""
    sim = Simulator(load_scene(config_dir() / f"{name}.yaml"))
    events = sim._event_step  # noqa: SLF001
    plain = events._call if events is not None else None  # noqa: SLF001
    timed = _TimedCall(events) if events is not None else None
    n = sim.scene.step_count
    took: list[list[float]] = [[] for _ in range(n)]
    call: list[list[float]] = [[] for _ in range(n)]
    kinds: list[str] = []
    internal: list[int] = []
    in_kernel: set[int] = set()  # the event steps the kernel took whole (`EventStep.settled`)
    for run in range(2 * runs + 2):  # the first two warm up; the odd runs time the kernel's call, the even the steps
        wrapped = run % 2 == 1 and timed is not None
        if events is not None:
            events._call = timed if wrapped else plain  # noqa: SLF001
        sim.reset()
        kinds.clear()
        internal.clear()
        for k in range(n):
            taken = events.taken if events is not None else 0
            settled = events.settled if events is not None else 0
            in_call = timed.seconds if wrapped else 0.0
            start = time.perf_counter()
            sim.step()
            seconds = time.perf_counter() - start
            kernel = events is not None and events.taken > taken and events.settled == settled
            kinds.append("first" if k == 0 else "kernel" if kernel else "event")
            if run == 0 and k and events is not None and events.settled > settled:
                in_kernel.add(k)
            if run < 2:
                continue
            if wrapped:
                call[k].append(1e6 * (timed.seconds - in_call))
                internal.append(timed.internal if kernel else 0)
            else:
                took[k].append(1e6 * seconds)
                if timed is None:
                    call[k].append(0.0)
    sums = dict.fromkeys(("whole", "first", "kernel", "kernel call", "event", "event call", "before", "n kernel",
                          "n event", "n before", "internal"), 0.0)
    first_event = kinds.index("event") if "event" in kinds else n
    for k, kind in enumerate(kinds):
        t, c = statistics.median(took[k]), statistics.median(call[k])
        sums["whole"] += t
        sums[kind] += t
        if kind != "first":
            sums[kind + " call"] += c
            sums["n " + kind] += 1
        if kind == "kernel":
            sums["internal"] += internal[k]
            if k < first_event:
                sums["before"] += t
                sums["n before"] += 1
    for count in (0, 1):  # the kernel call with no internal step (the dense output, projection, screen), and one
        calls = [statistics.median(call[k]) for k, kind in enumerate(kinds) if kind == "kernel" and internal[k] == count]
        sums[f"call {count}"] = statistics.median(calls) if calls else float("nan")
    sums["impacts"], sums["steps"], sums["n event in kernel"] = sim.impacts, n, len(in_kernel)
    return sums


def free_step(runs: int) -> float:
    """µs per step of the free scene under auto (rk6's lean compiled step), each step's median as in `profile_scene`."""
    sim = Simulator(load_scene(config_dir() / f"{FREE_SCENE}.yaml"))
    n = sim.scene.step_count
    took: list[list[float]] = [[] for _ in range(n)]
    for run in range(runs + 1):
        sim.reset()
        for k in range(n):
            start = time.perf_counter()
            sim.step()
            if run:
                took[k].append(1e6 * (time.perf_counter() - start))
    return sum(statistics.median(t) for t in took) / n


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m finger_sim.bench.contact_step_profile",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=RUNS)
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--attempts", action="store_true", help="also the event steps' attempts by phase")
    args = parser.parse_args(argv)
    free = free_step(args.runs)
    print(f"free step ({FREE_SCENE}, auto = rk6 lean): {free:.2f} µs; rk6 {RK6_RHS} right-hand sides per step, "
          f"DOP853 {DOP853_RHS} per accepted internal step (median of {args.runs} runs)")
    print("| scene | steps | µs/step (× free) | first step µs | kernel steps: n, µs/step, of it in the kernel "
          "| internal steps / output (rhs / rk6's) | kernel call with 0 / 1 internal steps µs | before contact µs/step (× free) | event steps: n, µs in all, "
          "of it in the kernel, taken whole by the kernel | impacts | share of the run: kernel steps / their Python / events / first |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.scenes:
        p = profile_scene(name, args.runs)
        n = p["steps"]
        nk = max(p["n kernel"], 1.0)
        per = p["whole"] / n
        internal = p["internal"] / nk
        before = p["before"] / max(p["n before"], 1.0)
        whole = p["whole"]
        print(f"| {name} | {n:.0f} | {per:.2f} ({per / free:.2f}×) | {p['first']:.0f} "
              f"| {p['n kernel']:.0f}, {p['kernel'] / nk:.2f}, {p['kernel call'] / nk:.2f} "
              f"| {internal:.2f} ({internal * DOP853_RHS / RK6_RHS:.1f}×) | {p['call 0']:.2f} / {p['call 1']:.2f} | {before:.2f} ({before / free:.2f}×) "
              f"| {p['n event']:.0f}, {p['event']:.0f}, {p['event call']:.0f}, {p['n event in kernel']:.0f} | {p['impacts']:.0f} "
              f"| {p['kernel call'] / whole:.0%} / {(p['kernel'] - p['kernel call']) / whole:.0%} "
              f"/ {p['event'] / whole:.0%} / {p['first'] / whole:.0%} |")
    if args.attempts:
        print()
        event_attempts.main(["--scenes", *args.scenes])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
