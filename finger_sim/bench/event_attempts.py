"""Where an event step's DOP853 attempts go: `python -m finger_sim.bench.event_attempts [--scenes ...]`.

An event step (a contact onset or release located in the step) costs its attempts: each is one DOP853
attempt of 12 right-hand sides (15 when accepted), and the kernel's event step is little else
(`contact_step_profile`: its time is about the attempts times one attempt's cost). The kernel takes the
same attempts as Python's loop (bit for bit), so they are counted there: the Simulator with the
kernel's event step and the compiled chunk of internal steps off (`_event_step`, `integrator._steps`:
every attempt through `DormandPrince853._attempt`, the same numbers). Each attempt of a step that
locates a crossing is sorted by phase:

- *pass 1*: `DormandPrince853.step`'s internal steps to the output time, split at the end of the internal
  step that straddles the located kink: the attempts up to it, and those past it, which the cut drops
  (`DormandPrince853.cut_at`);
- *cut*: the straddling step retaken to end at the kink;
- *after*: the rest of the step from the kink (continued or restarted).

A kink located at an internal step's end (no step straddles it) is not cut: its pass 1 counts whole as *up to
the kink*.
"""

from __future__ import annotations

import argparse
import bisect
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from finger_sim.bench.plan import config_dir
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

#: The scenes counted by default: the two whose event steps are most of the run past 2× a free step.
SCENES = ("grasp_impact", "grasp_rigid")
#: The phases of an event step's attempts (module docstring).
PHASES = ("pass 1 to the kink", "pass 1 past the kink", "cut", "after")


@dataclass
class Attempts:
    """One step's attempts: (start t in s, accepted) in order, by phase, and where pass 1 straddled the kink."""

    phases: dict[str, list[tuple[float, bool]]] = field(default_factory=lambda: {p: [] for p in PHASES[1:]})
    straddle_end: float | None = None  # the end (s) of pass 1's internal step across the kink, if it was cut

    def by_phase(self) -> dict[str, tuple[int, int]]:
        """(accepted, rejected) per phase of PHASES."""
        pass1 = self.phases[PHASES[1]]
        end = self.straddle_end
        split = {PHASES[0]: [a for a in pass1 if end is None or a[0] < end],
                 PHASES[1]: [a for a in pass1 if end is not None and a[0] >= end],
                 PHASES[2]: self.phases[PHASES[2]], PHASES[3]: self.phases[PHASES[3]]}
        return {p: (sum(ok for _, ok in rows), sum(not ok for _, ok in rows)) for p, rows in split.items()}


def count_scene(name: str) -> tuple[dict[int, Attempts], int, int]:
    """(step index → its attempts, for the steps that locate a crossing; the run's accepted and rejected
    attempts, the integrator's own counters) of one run of scene `name` on Python's counted loop."""
    sim = Simulator(load_scene(config_dir() / f"{name}.yaml"))
    sim._event_step = None  # noqa: SLF001  (Python's step, the same numbers as the kernel's)
    integ = sim.integrator
    integ._steps = None  # noqa: SLF001  (every attempt through `_attempt`)
    now = Attempts()
    phase = [PHASES[1]]
    attempt, cut_at, locate = integ._attempt, integ.cut_at, sim._locate  # noqa: SLF001
    located: set[int] = set()

    def counted_attempt(*args: Any) -> float:
        norm = attempt(*args)
        now.phases[phase[0]].append((args[7], norm < 1.0))  # args[7]: the attempt's start t
        return norm

    def counted_cut(s: float, *args: Any) -> Any:
        i = bisect.bisect_left(integ._history_starts, s) - 1  # noqa: SLF001  (`cut_at`'s straddling step)
        end = sum(integ._history[i][:2]) if i >= 0 else None  # noqa: SLF001  (t_old + h_old)
        phase[0] = PHASES[2]
        try:
            ended = cut_at(s, *args)
        finally:
            phase[0] = PHASES[3]
        if ended is not None:  # cut: pass 1's steps past the straddling one are dropped
            now.straddle_end = end
        return ended

    def counted_locate(*args: Any) -> Any:
        located.add(sim.step_index)
        return locate(*args)

    integ._attempt, integ.cut_at, sim._locate = counted_attempt, counted_cut, counted_locate  # noqa: SLF001
    steps: dict[int, Attempts] = {}
    for k in range(sim.scene.step_count):
        now = Attempts()
        phase[0] = PHASES[1]
        sim.step()
        if k in located:
            steps[k] = now
    return steps, integ.accepted, integ.rejected


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m finger_sim.bench.event_attempts",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    args = parser.parse_args(argv)
    print("Attempts accepted + rejected (Python's counted loop, the kernel's attempts):")
    print(f"| scene | event step | all | {' | '.join(PHASES)} |")
    print("|---|---:|---:|" + "---:|" * len(PHASES))
    for name in args.scenes:
        steps, accepted, rejected = count_scene(name)
        in_events = dropped = 0
        for k, attempts in steps.items():
            phases = attempts.by_phase()
            total = sum(a + r for a, r in phases.values())
            in_events += total
            dropped += sum(phases[PHASES[1]])
            cells = " | ".join(f"{a} + {r}" for a, r in phases.values())
            print(f"| {name} | {k} | {total} | {cells} |")
        print(f"| {name}: the run | {len(steps)} event steps | {accepted + rejected} ({accepted} + {rejected}) "
              f"| in event steps {in_events} | of them past the kink, dropped {dropped} | | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
