"""`method: auto`: pick the integrator from the scene's active effects and its dt, as the bench measured.

Three steps, each stated in the reason `choose_method` returns (and logs):

1. The scene's kind, from its active effects: *stiff* when the fastest mode of the spring
   and dampers (`stability.fastest_mode`) is not resolved by dt (|s|·dt > STIFF_MODE_DT);
   else *stops* when it has joint stops; else *discontinuous* when its torque switches
   (`Profile.breakpoints`); else *smooth*.
2. The rate: the tabulated rate at or below 1/dt (accuracy measured at an equal or larger
   step, so no better than what the scene gets), or the slowest one below all of them.
3. The cheapest method of `RECOMMENDATION[kind][rate]` whose worst error over the kind's
   bench scenes was within AUTO_TARGET, among those stable on the scene's fastest mode at
   its dt (`stability.stable_at`); if none reached the target, the most accurate stable
   one; if none is stable, FALLBACK (L-stable).

`RECOMMENDATION` is data produced by the bench: `finger-sim bench` (the full run) writes
the same literal under "The table behind method: auto" in docs/performance.md, and the
report says whether it still matches the one here; to regenerate, run the bench and paste
that block over the one below.
"""

from __future__ import annotations

import logging
import math

from finger_sim import kinematics
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene
from finger_sim.stability import fastest_mode, stable_at

LOG = logging.getLogger(__name__)

#: The error auto aims for, rad: the looser of the bench's two targets. 1e-6 rad (6e-5°)
#: is far below what an encoder or the model's own assumptions resolve; for 1e-9 name the
#: method the table's 1e-9 column gives.
AUTO_TARGET = 1e-6
#: A mode with |s|·dt above this is not resolved by the step (fewer than 2π steps per
#: period, or decaying within one step): the scene is stiff at that dt.
STIFF_MODE_DT = 1.0
#: L-stable, stable on every scene at every dt: the choice when nothing else is.
FALLBACK = "radau"

#: kind → rate (Hz) → ((method, worst error over the kind's scenes in rad, µs per step), ...),
#: cheapest first; produced by `finger-sim bench` (the full run of 2026-11-21 12:30 UTC in
#: docs/performance.md, on the project's development machine). Fixed-step methods only (no `adaptive`).
RECOMMENDATION: dict[str, dict[int, tuple[tuple[str, float, float], ...]]] = {
    "smooth": {
        100: (
            ("rk4", 0.0502, 15.7),
            ("rk6", 0.0191, 25.8),
            ("dop8", 0.00174, 42.8),
            ("radau", 0.000254, 301.0),
        ),
        1000: (
            ("euler", 0.121, 5.09),
            ("rk4", 7.47e-06, 15.2),
            ("rk6", 9.25e-09, 25.0),
            ("dop8", 7.56e-12, 42.8),
            ("rattle", 0.0013, 144.0),
            ("radau", 1.66e-08, 192.0),
        ),
        10000: (
            ("euler", 0.0119, 5.58),
            ("rk4", 5.12e-10, 14.9),
            ("rk6", 7.33e-12, 25.5),
            ("dop8", 7.59e-12, 42.7),
            ("radau", 7.74e-12, 160.0),
        ),
    },
    "discontinuous": {
        100: (
            ("rk4", 6.95e-08, 15.9),
            ("rk6", 7.11e-11, 26.2),
            ("dop8", 5.13e-14, 43.5),
            ("rattle", 0.000117, 140.0),
            ("radau", 2.8e-11, 221.0),
        ),
        1000: (
            ("euler", 0.000119, 5.56),
            ("rk4", 6.88e-12, 15.2),
            ("rk6", 3.41e-14, 25.1),
            ("dop8", 2.84e-14, 42.8),
            ("rattle", 1.17e-06, 120.0),
            ("radau", 3.36e-14, 174.0),
        ),
        10000: (
            ("euler", 1.18e-05, 5.57),
            ("rk4", 3.95e-14, 15.0),
            ("rk6", 4.44e-14, 24.8),
            ("dop8", 2.9e-14, 42.1),
            ("radau", 3.38e-14, 144.0),
        ),
    },
    "stiff": {
        100: (
            ("radau", 6.1e-06, 206.0),
        ),
        1000: (
            ("radau", 1.23e-06, 194.0),
        ),
        10000: (
            ("euler", 1.25e-05, 5.63),
            ("rk4", 4.78e-09, 15.5),
            ("rk6", 5.88e-11, 26.8),
            ("dop8", 1.06e-13, 44.4),
            ("radau", 2.88e-11, 130.0),
        ),
    },
    "stops": {
        100: (
            ("euler", 0.164, 6.63),
            ("rk4", 5.72e-06, 14.6),
            ("rk6", 4.71e-08, 23.0),
            ("dop8", 1.43e-11, 37.9),
            ("rattle", 0.00249, 171.0),
            ("radau", 4.33e-08, 219.0),
        ),
        1000: (
            ("euler", 0.0163, 5.45),
            ("rk4", 1.47e-09, 13.1),
            ("rk6", 6.34e-13, 20.0),
            ("dop8", 6.57e-13, 33.7),
            ("rattle", 3.42e-05, 105.0),
            ("radau", 4.01e-12, 147.0),
        ),
        10000: (
            ("euler", 0.00162, 5.47),
            ("rk4", 6.28e-13, 12.7),
            ("rk6", 6.5e-13, 20.0),
            ("dop8", 6.46e-13, 32.4),
            ("radau", 6.4e-13, 131.0),
        ),
    },
}

#: The scene kinds, in the order they are recognized.
KINDS = ("stiff", "stops", "discontinuous", "smooth")


def scene_kind(scene: Scene, root: complex) -> tuple[str, str]:
    """(kind, why) of a scene at its dt, given its fastest mode `root` (1/s)."""
    z = abs(root) * scene.dt
    if z > STIFF_MODE_DT:
        return "stiff", f"fastest mode |s|·dt = {z:.3g} > {STIFF_MODE_DT:g}, not resolved by the step"
    if scene.mcp_limits is not None:
        return "stops", f"MCP stops at {list(scene.mcp_limits)} rad"
    switches = scene.torque.breakpoints(0.0, scene.duration)
    if switches:
        return "discontinuous", f"{scene.torque.kind} torque switching {len(switches)} times"
    return "smooth", f"smooth {scene.torque.kind} torque, no stops, fastest mode |s|·dt = {z:.3g}"


def table_rate(rates: list[int], dt: float) -> tuple[int, str]:
    """The tabulated rate at or below 1/dt (Hz), or the slowest; with a note when extrapolating."""
    rate = 1.0 / dt
    below = [r for r in sorted(rates) if r <= rate * (1.0 + 1e-9)]
    if below:
        r = below[-1]
        return r, (f"{r:g} Hz" if math.isclose(r, rate, rel_tol=1e-9) else f"{rate:g} Hz (table row {r:g} Hz)")
    r = min(rates)
    return r, f"{rate:g} Hz (slower than any measured rate; table row {r:g} Hz)"


def choose_method(scene: Scene) -> tuple[str, str]:
    """(method, reason) for `method: auto`: the table's cheapest method within AUTO_TARGET that is stable at dt."""
    system = scene.build_system()
    root = fastest_mode(system, scene.mcp_limits or kinematics.assembly_range(scene.params))
    kind, why = scene_kind(scene, root)
    rows = RECOMMENDATION.get(kind, {})
    if not rows:
        return FALLBACK, f"{kind} scene ({why}); no measurements for it: {FALLBACK}, stable at every dt"
    rate, rate_text = table_rate(list(rows), scene.dt)
    stable, skipped = [], []
    for method, error, cost in rows[rate]:
        cls = METHODS.get(method)
        if cls is None:
            continue
        if stable_at(cls, root, scene.dt):
            stable.append((method, error, cost))
        else:
            skipped.append(method)
    unstable = f"; unstable here: {', '.join(skipped)}" if skipped else ""
    within = [row for row in stable if row[1] <= AUTO_TARGET]
    if within:
        method, error, cost = within[0]
        cheaper = [row for row in stable if row[2] < cost]
        missed = "".join(f"; cheaper {m} missed it ({e:.1e} rad)" for m, e, _ in cheaper)
        reason = (
            f"{kind} scene ({why}); at {rate_text} the bench measured {method} as the cheapest method within "
            f"{AUTO_TARGET:g} rad (worst {error:.1e} rad, {cost:.0f} µs/step){missed}{unstable}"
        )
    elif stable:
        method, error, cost = min(stable, key=lambda row: row[1])
        reason = (
            f"{kind} scene ({why}); at {rate_text} no stable method reached {AUTO_TARGET:g} rad in the bench: "
            f"{method} is the most accurate (worst {error:.1e} rad, {cost:.0f} µs/step){unstable}"
        )
    else:
        method = FALLBACK
        reason = f"{kind} scene ({why}); at {rate_text} no tabulated method is stable{unstable}: {FALLBACK}, L-stable"
    LOG.info("method auto → %s: %s", method, reason)
    return method, reason
