"""Build numba's on-disk cache of every compiled kernel now, at set-up, not in a user's first run.

    python -m finger_sim.kernel.warm

The Makefile's install step runs it, so `make run` (the node's compiled step) and the first
`simulate`, `sweep` or `rollout` load the cache (well under a second) instead of compiling
(6-25 s). numba keys its cache by each function's argument types, so the warm-up makes the
same calls, with the same types, as those paths do: a short run of each shipped kind of scene
(smooth, with a stop, with contact; rk6, dop853: the Simulator's compiled event step, `kernel.event_step`,
among them) on the compiled kernel, a batch, a rollout and
the task sweeps' closed loops (grip PI, and the drive's grip_current and grip_voltage).
Prints one line: what was warmed and how long it took.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from finger_sim.scene import load_scene

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Scenes whose compiled runs touch every kernel entry point: smooth (fast_run, fast_step), a
#: stop (rk_step_tuple per event step), contact (the contact force law), and our DOP853.
SCENES = ("paper_flexion", "paper_to_stop", "grasp_cylinder")
#: Steps of each warm-up run: enough to reach every code path's first call.
STEPS = 20
#: The stick–slip warm-up's inductance (H) and voltage (V): the fingertip driven (spec §8's default drive)
#: onto the table of config/friction/hold_table.yaml.
STICK_SLIP_INDUCTANCE = 0.02
STICK_SLIP_VOLTAGE = {"type": "constant", "value": 2.0}


def warm() -> list[str]:
    """Run every compiled entry point once; the names of what was warmed."""
    from finger_sim.batch import run_batch
    from finger_sim.rollouts import rollout
    from finger_sim.errors import StabilityError
    from finger_sim.simulate import Simulator, simulate
    from finger_sim.tasks.batch import run_task_rows
    from finger_sim.tasks.controllers import grip_pi, grip_voltage
    from finger_sim.tasks.current_grip import grip_current
    from finger_sim.tasks.schema import load_task

    done = []
    for name in SCENES:
        scene = load_scene(CONFIG / f"{name}.yaml")
        short = scene.with_overrides(duration=STEPS * scene.dt)
        simulate(short, kernel="compiled")  # the whole-run loop (kernel.runner)
        for method in ("rk6", "dop853"):
            try:
                sim = Simulator(short.with_overrides(method=method), kernel="compiled")
            except StabilityError:  # a named explicit method that cannot resolve this scene's contact
                continue
            for _ in range(STEPS):
                sim.step()
            sim.step(0.0)  # a held command, as the node steps
        run_batch([short])
        done.append(name)
    # the whole run to its rest on the stop (from ~0.43 s): the stretches' loops (`kernel.event_run`)
    simulate(load_scene(CONFIG / "paper_to_stop.yaml"), kernel="compiled")
    paper = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(duration=STEPS * 0.001)
    run_batch([paper.with_overrides(method="euler")])  # a row of the batch's event-checked loop (run_rows)
    rollout(paper, nstep=STEPS)
    rollout(paper, control=np.zeros((2, STEPS)))
    hold = load_task(CONFIG / "tasks" / "hold_cup.yaml")
    hold = dataclasses.replace(hold, scene=hold.scene.with_overrides(duration=STEPS * hold.scene.dt))
    run_task_rows(hold, grip_pi, [("a", {}), ("b", {"ki": 2.0})])  # the gain sweep's closed loop
    for name, factory in (("hold_current", grip_current), ("hold_voltage_off", grip_voltage)):
        task = load_task(CONFIG / "tasks" / f"{name}.yaml")
        task = dataclasses.replace(task, scene=task.scene.with_overrides(duration=STEPS * task.scene.dt))
        run_task_rows(task, factory, [("a", {}), ("b", {"ki": 2.0})])  # the drive tasks' closed loop
    _warm_stick_slip()
    _warm_inductive_lean()
    return [*done, "batch", "rollout", "task sweep", "drive task sweep", "stick-slip (L = 0, L > 0)",
            "the inductive drive's lean step"]


def _warm_inductive_lean() -> None:
    """The lean step of an inductive drive without gaps (`kernel.drive.inductive_fast_step`), as the node
    steps it: the scene's profile and a held command."""
    from finger_sim.scene import scene_from_dict
    from finger_sim.simulate import Simulator

    free = scene_from_dict({"model": {"drive": {"inductance": STICK_SLIP_INDUCTANCE}},
                            "input": {"voltage": STICK_SLIP_VOLTAGE}, "duration": STEPS * 0.001})
    sim = Simulator(free, kernel="compiled")
    for _ in range(STEPS):
        sim.step()
    sim.step(0.0)


def _warm_stick_slip() -> None:
    """The stick–slip steps: our DOP853 on the friction law, and with a drive the driven DOP853 (L = 0)
    and the inductive Runge–Kutta step (L > 0, `kernel.drive.inductive_step_tuple`, whose first call
    otherwise compiles some twenty functions in the user's run)."""
    from finger_sim.scene import scene_from_dict
    from finger_sim.simulate import simulate

    table = load_scene(CONFIG / "friction" / "hold_table.yaml").with_overrides(duration=STEPS * 0.001)
    simulate(table, kernel="compiled")
    data = table.to_dict()
    for drive in ({}, {"inductance": STICK_SLIP_INDUCTANCE}):
        driven = {**data, "model": {**data["model"], "drive": drive}, "input": {"voltage": STICK_SLIP_VOLTAGE}}
        simulate(scene_from_dict(driven), kernel="compiled")


def main() -> None:
    start = time.perf_counter()
    names = warm()
    print(f"numba cache warm: {', '.join(names)} ({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
