"""The whole-run fast path: many Simulator steps inside one kernel call.

Used by offline `simulate()`, `streaming.stream_csv` (block by block) and batch callers:
on a smooth scene (no events) with a compiled torque profile, the compiled kernel loops
over the steps and evaluates τ itself (`numerics.fast_run`); it stops before a step with a
torque switch inside, which goes through `Simulator.step` (split there), and goes on.
Our DOP853 answers a whole smooth stretch of the output grid in one call. Same numbers as
stepping one by one, bit for bit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from finger_sim.inputs import Profile
from finger_sim.kernel.layout import BREAKPOINT, OK

if TYPE_CHECKING:
    from finger_sim.simulate import Simulator


def can_run(sim: "Simulator") -> bool:
    """Whether `advance` loops `sim` in the kernel: the Simulator's compiled fast path with a
    compiled profile, or our DOP853; on a smooth scene."""
    fast = sim.fast_stepper
    smooth = all(e.smooth for e in sim.system.elements)
    return smooth and ((fast is not None and fast.profile is not None) or hasattr(sim.integrator, "run_grid"))


def advance(sim: "Simulator", n: int) -> np.ndarray:
    """Step `sim` n times under its scene's torque profile; the (n, 6) states (q, q') after each step."""
    if not can_run(sim):
        return _stepped(sim, n)
    if hasattr(sim.integrator, "run_grid"):
        return _advance_grid(sim, n)
    fast = sim.fast_stepper
    assert fast is not None
    xs = np.empty((n + 1, 6))
    xs[0] = (*sim.q, *sim.v)
    done = 0
    while done < n:
        status, count, end = fast.run(sim.step_index, xs[done:])
        if count:
            done += count
            last = xs[done].tolist()
            sim.q, sim.v, sim.torque = tuple(last[:3]), tuple(last[3:]), end
            sim.step_index += count
        if status == BREAKPOINT:  # a switch inside the next step: the Simulator splits it
            state = sim.step()
            done += 1
            xs[done] = (*state.q, *state.v)
        elif status != OK:
            fast.fail(status, sim.step_index, sim.q)
    return xs[1:]


def _stepped(sim: "Simulator", n: int) -> np.ndarray:
    for stepping in sim.mode_steppings:  # an owner that takes stretches of its modes at once
        xs = stepping.run_states(sim, n)
        if xs is not None:
            return xs
    if sim._event_step is not None:  # noqa: SLF001  (a scene with events: stretches in one kernel call)
        from finger_sim.kernel import run_stretch

        return run_stretch.advance(sim, n)
    return np.array([(*s.q, *s.v) for s in (sim.step() for _ in range(n))]).reshape(n, 6)


def _advance_grid(sim: "Simulator", n: int) -> np.ndarray:
    """An adaptive integrator's run: one call over the output grid when no torque breakpoint
    falls inside it (else step by step). Grid times as `Simulator.step` forms them."""
    profile, dt, start = sim.scene.torque, sim.dt, sim.step_index
    t0, t1 = start * dt, (start + n) * dt
    segment = profile.on_segment(t0, t1) if isinstance(profile, Profile) else profile
    if segment is not profile or (isinstance(profile, Profile) and profile.breakpoints(t0, t1)):
        # not one smooth function (a piecewise-constant profile): `step` restarts at every step
        return _stepped(sim, n)
    k = np.arange(start, start + n + 1, dtype=np.float64)
    lows, highs = k[:-1] * dt, k[1:] * dt
    times = np.concatenate(([t0], lows + (highs - lows)))  # t + (t1 − t), as each step's end
    out = sim.integrator.run_grid(times, sim.q, sim.v, segment)  # type: ignore[attr-defined]
    sim.q, sim.v = tuple(out[-1, :3].tolist()), tuple(out[-1, 3:].tolist())
    sim.step_index = start + n
    sim.torque = segment(t1)
    return out
