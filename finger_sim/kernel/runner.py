"""The whole-run fast path: many Simulator steps inside one kernel call.

Used by offline `simulate()` (and batch callers): where no event can occur (a smooth scene)
and no torque breakpoint falls inside a step, the steps' stage torques are evaluated in
Python up front and the compiled kernel loops over the steps. A step with a breakpoint
inside goes through `Simulator.step`. Same numbers as stepping one by one, bit for bit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from finger_sim.errors import SimulationDiverged
from finger_sim.inputs import Profile

if TYPE_CHECKING:
    from finger_sim.simulate import Simulator


def can_run(sim: "Simulator") -> bool:
    """Whether `advance` may loop `sim` in the kernel: a compiled fixed-step method or dop853, a smooth scene."""
    integrator = sim.integrator
    return (hasattr(integrator, "run") or hasattr(integrator, "run_grid")) and all(e.smooth for e in sim.system.elements)


def advance(sim: "Simulator", n: int) -> np.ndarray:
    """Step `sim` n times under its scene's torque profile; the (n, 6) states (q, q') after each step."""
    from finger_sim.simulate import BREAK_EPS

    if not can_run(sim):
        return np.array([(*s.q, *s.v) for s in (sim.step() for _ in range(n))]).reshape(n, 6)
    integrator, profile, dt = sim.integrator, sim.scene.torque, sim.dt
    if hasattr(integrator, "run_grid"):
        return _advance_grid(sim, n)
    nodes = integrator.nodes  # type: ignore[attr-defined]
    out = np.empty((n, 6))
    t0s: list[float] = []
    hs: list[float] = []
    taus: list[list[float]] = []
    start = sim.step_index
    eps = BREAK_EPS * dt
    checks_breaks = isinstance(profile, Profile)

    def flush(upto: int) -> None:
        """Run the collected steps (those ending at step `upto` of this call) in the kernel."""
        if not t0s:
            return
        count = len(t0s)
        xs = integrator.run(np.array(t0s), np.array(hs), np.array(taus), (*sim.q, *sim.v))  # type: ignore[attr-defined]
        finite = np.isfinite(xs).all(axis=1)
        if not finite.all():
            bad = upto - count + int(np.argmin(finite))
            raise SimulationDiverged(f"non-finite state (step {start + bad})", method=sim.method, t=(start + bad) * dt, dt=dt)
        out[upto - count: upto] = xs[1:]
        sim.q, sim.v = tuple(xs[-1, :3].tolist()), tuple(xs[-1, 3:].tolist())
        sim.step_index = start + upto
        t0s.clear(), hs.clear(), taus.clear()

    for i in range(n):
        k = start + i
        t0, t1 = k * dt, (k + 1) * dt
        if checks_breaks and any(t0 + eps < b < t1 - eps for b in profile.breakpoints(t0, t1)):
            flush(i)
            s = sim.step()
            out[i] = (*s.q, *s.v)
            continue
        segment = profile.on_segment(t0, t1)
        h = t1 - t0
        t0s.append(t0)
        hs.append(h)
        taus.append([segment(t0 + c * h) for c in nodes])
        sim.torque = segment(t1)
    flush(n)
    return out


def _advance_grid(sim: "Simulator", n: int) -> np.ndarray:
    """An adaptive integrator's run: one call over the output grid when no torque breakpoint
    falls inside it (else step by step). Grid times as `Simulator.step` forms them."""
    profile, dt, start = sim.scene.torque, sim.dt, sim.step_index
    t0, t1 = start * dt, (start + n) * dt
    segment = profile.on_segment(t0, t1) if isinstance(profile, Profile) else profile
    if segment is not profile or (isinstance(profile, Profile) and profile.breakpoints(t0, t1)):
        # not one smooth function (a piecewise-constant profile): `step` restarts at every step
        return np.array([(*s.q, *s.v) for s in (sim.step() for _ in range(n))]).reshape(n, 6)
    k = np.arange(start, start + n + 1, dtype=np.float64)
    lows, highs = k[:-1] * dt, k[1:] * dt
    times = np.concatenate(([t0], lows + (highs - lows)))  # t + (t1 − t), as each step's end
    out = sim.integrator.run_grid(times, sim.q, sim.v, segment)  # type: ignore[attr-defined]
    sim.q, sim.v = tuple(out[-1, :3].tolist()), tuple(out[-1, 3:].tolist())
    sim.step_index = start + n
    sim.torque = segment(t1)
    return out
