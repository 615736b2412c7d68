"""A gain sweep of the grip PI on one task: today's loop against two lockstep batch forms, side by side.

    python -m finger_sim.bench.gain_sweep_bench [--task config/tasks/hold_cup.yaml] [--gains 8] [--repeats 3]

Every path runs the same closed loop at the ROS path's lockstep timing (every step sampled, the
answer acting over the next step: `ros_runner.lockstep_task`) for `gains` (kp, ki) pairs:

- **loop**: today's `finger-sim tasks --vary`: `run_task` once per gain pair (the controller is
  `grip_pi`, finger_grip_controller's law, one Python object per run);
- **rollout**: `finger_sim.rollout` stepped one control period at a time over all gain pairs as
  its rows, the PI vectorised in numpy (`BatchPi`) between calls; each call restarts from the rows'
  (θ1, θ1'), which is all that rollout's public API takes as a state;
- **lockstep**: one Simulator per gain pair, all stepped in lockstep, the PI vectorised in numpy:
  what rollout itself does for a contact scene (its rows with events are stepped by their
  Simulators), without the per-call set-up.

Timings are process CPU per finger-step, medians of `repeats`, the paths interleaved so that
outside load hits all alike. Agreement: max |F − F_loop| (N) of each path's grip force over all
rows and steps.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError
from finger_sim.rollouts import rollout
from finger_sim.runtime.grip import CLOSING_TORQUE, CONTACT_THRESHOLD, MAX_TORQUE
from finger_sim.simulate import Simulator, output_names, output_values
from finger_sim.tasks.controllers import grip_pi
from finger_sim.tasks.ros_runner import lockstep_task
from finger_sim.tasks.runner import run_task
from finger_sim.tasks.schema import Task, load_task

TASK = Path(__file__).resolve().parents[2] / "config" / "tasks" / "hold_cup.yaml"
#: The swept gains: kp (N·m/N) and ki (N·m/(N·s)) spread around the shipped 0.005 and 4.
KP_RANGE = (0.0025, 0.01)
KI_RANGE = (2.0, 8.0)


class BatchPi:
    """finger_grip_controller's law (runtime.grip.GripController: close, then PI with clamping
    anti-windup) for a setpoint held from t = 0, on arrays: one row per gain pair."""

    def __init__(self, kp: np.ndarray, ki: np.ndarray, setpoint: float, dt: float) -> None:
        self.kp, self.ki, self.setpoint, self.dt = kp, ki, setpoint, dt
        self.holding = np.zeros(kp.shape, dtype=bool)
        self.integral = np.zeros(kp.shape)

    def __call__(self, force: np.ndarray) -> np.ndarray:
        error = self.setpoint - force
        touched = ~self.holding & (force > CONTACT_THRESHOLD)
        self.integral = np.where(touched, np.clip(CLOSING_TORQUE - self.kp * error, -MAX_TORQUE, MAX_TORQUE),
                                 self.integral)
        self.holding |= touched
        trial = self.integral + self.ki * error * self.dt
        up = np.minimum(trial, np.maximum(self.integral, MAX_TORQUE - self.kp * error))
        down = np.maximum(trial, np.minimum(self.integral, -MAX_TORQUE - self.kp * error))
        trial = np.where(error > 0.0, up, np.where(error < 0.0, down, trial))
        self.integral = np.where(self.holding, np.clip(trial, -MAX_TORQUE, MAX_TORQUE), self.integral)
        u = np.clip(self.kp * error + self.integral, -MAX_TORQUE, MAX_TORQUE)
        return np.where(self.holding, u, CLOSING_TORQUE)


def gains(count: int) -> tuple[np.ndarray, np.ndarray]:
    """`count` (kp, ki) pairs on a log-spaced grid (as square as count allows)."""
    side = int(np.ceil(np.sqrt(count)))
    kp, ki = np.meshgrid(np.geomspace(*KP_RANGE, side), np.geomspace(*KI_RANGE, side))
    return kp.ravel()[:count], ki.ravel()[:count]


def by_loop(task: Task, kp: np.ndarray, ki: np.ndarray) -> np.ndarray:
    runs = [run_task(task, grip_pi, params={"kp": p, "ki": i}) for p, i in zip(kp.tolist(), ki.tolist())]
    return np.array([r.samples[GRIP_FORCE.name] for r in runs])


def by_rollout(task: Task, kp: np.ndarray, ki: np.ndarray) -> np.ndarray:
    scene, n = task.scene, task.scene.step_count
    law = BatchPi(kp, ki, task.setpoints[0][1], scene.dt)
    state = np.tile([scene.theta1, scene.theta1_dot], (len(kp), 1))
    force = np.zeros((len(kp), n + 1))
    for k in range(n):
        try:
            res = rollout(scene, control=law(force[:, k])[:, None], initial_state=state, nstep=1)
        except ConfigError as exc:  # a restart in contact: rollout checks each start's clearance
            raise Refused(k, str(exc)) from None
        state = np.column_stack([res.q[:, 1, 0], res.v[:, 1, 0]])
        force[:, k + 1] = res.outputs[GRIP_FORCE.name][:, 1]
    return force


def by_lockstep(task: Task, kp: np.ndarray, ki: np.ndarray) -> np.ndarray:
    scene, n = task.scene, task.scene.step_count
    law = BatchPi(kp, ki, task.setpoints[0][1], scene.dt)
    sims = [Simulator(scene) for _ in kp]
    column = output_names(sims[0].system.elements, sims[0].q).index(GRIP_FORCE.name)
    force = np.zeros((len(kp), n + 1))
    for k in range(n):
        for sim, u in zip(sims, law(force[:, k]).tolist()):
            sim.step(u)
        force[:, k + 1] = [output_values(s.system.elements, s.time, s.q, s.v)[column] for s in sims]
    return force


class Refused(Exception):
    """The path cannot go on at step `step` (why: `reason`)."""

    def __init__(self, step: int, reason: str) -> None:
        super().__init__(f"refused at step {step}: {reason}")
        self.step, self.reason = step, reason
        self.cpu = 0.0  # process CPU s spent before the refusal


PATHS = {"loop": by_loop, "rollout": by_rollout, "lockstep": by_lockstep}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", type=Path, default=TASK)
    ap.add_argument("--gains", type=int, default=8, help="gain pairs (rows)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    task = lockstep_task(load_task(args.task))
    if len(task.setpoints) != 1 or task.scene.tip_force_profile or any(
            o.properties.break_force is not None for o in task.scene.objects):
        raise SystemExit("gain_sweep_bench: a task with one setpoint, no disturbance and nothing breakable")
    kp, ki = gains(args.gains)
    steps = len(kp) * task.scene.step_count
    cpu: dict[str, list[float]] = {name: [] for name in PATHS}
    forces: dict[str, np.ndarray] = {}
    refused: dict[str, Refused] = {}
    for i in range(args.repeats + 1):  # the first round warms numba and the set-up caches up
        for name, run in PATHS.items():
            if name in refused:
                continue
            start = time.process_time()
            try:
                forces[name] = run(task, kp, ki)
            except Refused as exc:  # timed up to the refusal (the first round: warm after the loop's runs)
                exc.cpu = time.process_time() - start
                refused[name] = exc
                continue
            if i:
                cpu[name].append(time.process_time() - start)
    loop = statistics.median(cpu["loop"])
    print(f"{task.name}: {len(kp)} gain pairs × {task.scene.step_count} steps, medians of {args.repeats}")
    print("| path | CPU s | µs per finger-step | vs loop | max |F − F_loop| (N) |")
    print("|---|---|---|---|---|")
    for name, exc in refused.items():
        per_step = exc.cpu / max(exc.step * len(kp), 1) * 1e6
        print(f"| {name} | — | {per_step:.1f} over the {exc.step} steps before | {per_step / (loop / steps * 1e6):.1f}× | "
              f"refused at step {exc.step} (t = {exc.step * task.scene.dt:g} s): {exc.reason} |")
    for name in (p for p in PATHS if p not in refused):
        med = statistics.median(cpu[name])
        dev = float(np.max(np.abs(forces[name] - forces["loop"])))
        print(f"| {name} | {med:.3f} | {med / steps * 1e6:.1f} | {med / loop:.2f}× | {dev:.3g} |")


if __name__ == "__main__":
    main()
