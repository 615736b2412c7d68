"""`finger_sim.rollout` against `mujoco.rollout`, side by side in one process: CPU and accuracy.

    python -m finger_sim.bench.rollout_bench [--nbatch 2000] [--repeats 3] [--threads 2]

Both roll out nbatch copies of the paper's run (config/paper_flexion.yaml: 300 steps of
1 ms) and keep every step's state. finger_sim: the scene's own torque ramp, its auto method
(rk6). MuJoCo (`bench.mujoco_peer`): the same finger as an MJCF with the tightest stable loop
closure, RK4 at the same 1 ms step, ctrl held at each step's midpoint torque (the peer's
second-order hold), `nthread` MjData. A second case gives both a random held control per
row and step (sampling-based MPC). Timings are process CPU (every thread) per finger-step,
medians of `repeats`, the paths interleaved so that outside load hits all alike. Accuracy:
max |θ − θ_ref| over the run's 301 samples of row 0, θ_ref scipy's DOP853 at rtol 1e-13
(`bench.reference.solve`).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import mujoco
import mujoco.rollout
import numpy as np

from finger_sim.bench.mujoco_peer import TORQUE_TIME_IN_STEP, MujocoFinger, tight_equality
from finger_sim.bench.reference import REFERENCE_RTOL, solve
from finger_sim.rollouts import rollout
from finger_sim.scene import load_scene

SCENE = Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml"
MUJOCO_INTEGRATOR = "RK4"
#: The random controls' range, N·m: the paper's ramp spans 1-4 N·mm.
CONTROL_RANGE = (0.0, 0.004)
#: Rows of the warm-up call of each path.
WARM_UP_ROWS = 16


def _cpu(run):  # type: ignore[no-untyped-def]
    start = time.process_time()
    out = run()
    return time.process_time() - start, out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nbatch", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    scene = load_scene(SCENE)
    nstep, dt, n = scene.step_count, scene.dt, args.nbatch

    finger = MujocoFinger(scene.params, timestep=dt, integrator=MUJOCO_INTEGRATOR, equality=tight_equality(dt),
                          spring_stiffness=scene.spring_stiffness)
    model = finger.model
    datas = [mujoco.MjData(model) for _ in range(args.threads)]
    start = finger.make_data()
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, start, state0, spec)
    offset = TORQUE_TIME_IN_STEP[MUJOCO_INTEGRATOR]
    ramp = np.array([scene.torque((k + offset) * dt) for k in range(nstep)])
    mj_ctrl = np.broadcast_to(ramp[None, :, None], (n, nstep, model.nu)).copy()
    mj_init = np.tile(state0, (n, 1))
    rng = np.random.default_rng(0)
    random_ctrl = rng.uniform(*CONTROL_RANGE, (n, nstep))
    zeros = np.zeros((n, 2))

    cases = {
        "finger_sim.rollout, paper run": lambda k: rollout(scene, initial_state=zeros[:k], nthread=args.threads),
        "mujoco.rollout, paper run": lambda k: mujoco.rollout.rollout(model, datas, mj_init[:k], mj_ctrl[:k]),
        "finger_sim.rollout, random control": lambda k: rollout(scene, control=random_ctrl[:k], nthread=args.threads),
        "mujoco.rollout, random control": lambda k: mujoco.rollout.rollout(model, datas, mj_init[:k],
                                                                          random_ctrl[:k, :, None]),
    }
    for run in cases.values():  # warm up on a few rows: numba's cache load, MuJoCo's thread pool
        run(WARM_UP_ROWS)
    times: dict[str, list[float]] = {name: [] for name in cases}
    last: dict[str, object] = {}
    for _ in range(args.repeats):
        for name, run in cases.items():
            cpu, last[name] = _cpu(lambda: run(n))
            times[name].append(cpu)

    ref = solve(scene, method="DOP853", rtol=REFERENCE_RTOL).states(np.arange(nstep + 1) * dt)[:, :3]
    ours = last["finger_sim.rollout, paper run"].q[0]  # type: ignore[attr-defined]
    mj_state = last["mujoco.rollout, paper run"][0]  # type: ignore[index]
    qpos = mj_state[0, :, 1: 1 + model.nq]  # FULLPHYSICS: time, qpos, qvel, ...
    theirs = np.vstack([finger.to_paper(start.qpos), finger.to_paper(qpos)])
    errors = {"finger_sim.rollout, paper run": float(np.abs(ours - ref).max()),
              "mujoco.rollout, paper run": float(np.abs(theirs - ref).max())}

    steps = n * nstep
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; nbatch {n}, {nstep} steps of {dt:g} s, "
          f"{args.threads} threads, medians of {args.repeats}; mujoco {mujoco.__version__}")
    print("| path | CPU µs / finger-step | CPU s | max \\|θ − θ_ref\\| rad |")
    print("|---|---:|---:|---:|")
    for name, samples in times.items():
        med = statistics.median(samples)
        err = f"{errors[name]:.2e}" if name in errors else "—"
        print(f"| {name} | {1e6 * med / steps:.3f} | {med:.3f} | {err} |")
    ratio = statistics.median(times["mujoco.rollout, paper run"]) / statistics.median(
        times["finger_sim.rollout, paper run"])
    print(f"\nCPU ratio mujoco/finger_sim on the paper run: {ratio:.1f}×; "
          f"accuracy ratio: {errors['mujoco.rollout, paper run'] / errors['finger_sim.rollout, paper run']:.3g}×")


if __name__ == "__main__":
    main()
