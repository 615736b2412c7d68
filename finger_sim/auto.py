"""`method: auto`: pick the integrator from the scene's active effects and its dt, as the bench measured.

Three steps, each stated in the reason `choose_method` returns (and logs):

1. The scene's kind, from its active effects: *stiff* when the fastest mode of its force
   elements (`stability.fastest_mode`) is not resolved by dt (|s|·dt > STIFF_MODE_DT);
   else *stops* when an element has events (`smooth` is False: stops, contact); else
   *discontinuous* when its torque switches (`Profile.breakpoints`); else *smooth*.
2. The rate: the tabulated rate at or below 1/dt (accuracy measured at an equal or larger
   step, so no better than what the scene gets), or the slowest one below all of them.
3. `pick`: among the methods of the table's row whose worst error over the kind's bench scenes
   was within AUTO_TARGET and that are stable on the scene's fastest mode at its dt
   (`stability.stable_at`), the most accurate of those costing at most COST_MARGIN times the
   cheapest of them (costs closer than timing noise count as equal); if none reached the target,
   the most accurate stable one; if none is stable, FALLBACK (L-stable). No pick is dearer than
   another stable row at the same or better error. The bench report calls the same `pick`.

Contact (spec §7) adds a mode of 10²–10⁴ rad/s that exists only while a phalanx touches an
object. Before the accuracy promise, auto stepped such a scene with the table's explicit choice split into m
substeps in contact (`contact_substeps`, still what `finger_sim.batch` asks); that missed the
tolerance on scenes the table had not seen (up to 1.4e-4 rad), so contact now goes to the
error-controlled path below.

The promise: `auto` delivers the scene's `integrator.tolerance` (AUTO_TARGET by default) on θ,
checked per run rather than per table. The table's fixed-step method is kept only where the scene has no
events and is not stiff (kinds *smooth* and *discontinuous*: the fast compiled path) and the bench measured it
TABLE_MARGIN times inside the tolerance; every other scene (stops, contact, stiff) is stepped by the
error-controlled compiled DOP853 (`ERROR_CONTROLLED`, `error_control`) at rtol = atol =
ERROR_CONTROL_PER_TOLERANCE·tolerance, with every event located inside the step by the Simulator, and its
run reports the error it estimates (`DormandPrince853.error_estimate`), not the table's.

The table is data produced by the bench: `finger-sim bench` (the full run) writes
finger_sim/data/recommendation.json (`save_recommendation`), which `load_recommendation`
reads.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

from finger_sim import kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import EFFECTS, build_elements
from finger_sim.effects.base import has_kinks
from finger_sim.integrators import METHODS
from finger_sim.scene import AUTO, Scene
from finger_sim.stability import SAMPLES, TOGGLE_MARGIN, fastest_mode, inside_object, mcp_range, modal_roots, stable_at

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
#: In contact, each substep h = dt/m resolves the contact mode: |s|·h ≤ this. Measured at dt = 1 ms
#: (README "Grasping", max θ1 error vs the tight reference / cost vs the free step): 1.0 → rk4×5 on
#: grasp_rigid, 8e-5 rad on grasp_impact; 0.5 → 1e-5 / 3e-6 rad; 0.25 → 3e-6 / 8e-7 rad at ≤ 1.9×.
CONTACT_SUBSTEP_MODE_DT = 0.25
#: Most substeps per step in contact; a contact stiffer than that at dt gets FALLBACK.
MAX_CONTACT_SUBSTEPS = 32
#: FALLBACK in contact: each substep h = dt/m resolves the contact's oscillatory mode, ω_c·h ≤ this.
IMPLICIT_CONTACT_MODE_DT = 0.5
#: The error-controlled method auto steps every scene with events (stops, contact) or a stiff mode with:
#: compiled, stable wherever its error control lets it be, and far cheaper than radau.
ERROR_CONTROLLED = "dop853"
#: Added to auto's reason where an element has no compiled form: the error-controlled path evaluates its stages
#: in Python (`DormandPrince853.compiled`), the same promise at several times the CPU.
PYTHON_STAGES_NOTE = ("; an element without a compiled form (objects' different contact laws, a motion): its stages run "
                      "in Python, several times slower")
#: Its rtol = atol per unit of the promised global tolerance. The global error is the sum of the local
#: errors along the run (hundreds of internal steps, each error-controlled) plus event location; measured
#: on the hard scenes (config/hard/, docs/auto_accuracy.md) at 1e-3·1e-6 rad: 3e-10 to 1.7e-7
#: rad against a tight reference, so 1e-3 keeps 5× margin on the worst (elastic stops at 50 rad/s).
ERROR_CONTROL_PER_TOLERANCE = 1e-3
#: |s|·h at which DOP853's error control settles on a mode s it cannot follow (its stability boundary on the
#: negative real axis, ≈ 6): the internal steps per output step are about |s|·dt / this. Measured on
#: stiff_spring (|s|·dt = 10.8): 1.8 attempts per 1 ms step.
DOP853_STABILITY = 6.0
#: CPU per internal DOP853 attempt through `Simulator.step`, µs (docs/auto_accuracy.md: stiff_spring,
#: 25 µs per step at 1.8 attempts, on the shared machine), and the event bookkeeping of a contact step.
ATTEMPT_US, EVENT_STEP_US = 14.0, 20.0
#: Share of a real-time period the stepping may take (the rest: messages, the log).
REALTIME_SHARE = 0.5
#: The table's fixed-step method is trusted on a scene it did not measure only when its worst error
#: over the kind's bench scenes is this many times inside the tolerance.
TABLE_MARGIN = 10.0
#: Costs of the table's rows within this factor of the cheapest row within the target count as equal in
#: `pick` (the most accurate of them wins): the same row's µs/step moved by 10–30 % between the last four
#: full bench runs (finger_sim/data/recommendation.json's history, e.g. discontinuous at 100 Hz: rk4 1.99,
#: 1.94, 3.55, 2.03; rk6 2.28, 2.59, 2.72, 2.28), enough to flip a pick decided by a few percent.
COST_MARGIN = 1.15
#: The measured table, package data written by the bench.
RECOMMENDATION_FILE = Path(__file__).parent / "data" / "recommendation.json"


class Row(NamedTuple):
    """One candidate of the table: a method, its worst error over the kind's bench scenes (rad)
    and its cost (µs per step)."""

    method: str
    error: float
    cost: float


#: kind → rate (Hz) → rows, cheapest first.
Table = dict[str, dict[int, tuple[Row, ...]]]


def load_recommendation(path: Path = RECOMMENDATION_FILE) -> Table:
    """The recommendation table from its JSON file (see `save_recommendation`)."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))["recommendation"]
    return {kind: {int(rate): tuple(Row(*row) for row in rows) for rate, rows in by_rate.items()}
            for kind, by_rate in data.items()}


def save_recommendation(table: Mapping[str, Mapping[int, Sequence[Sequence[object]]]], about: str,
                        path: Path = RECOMMENDATION_FILE) -> None:
    """Write the table as JSON, one candidate per line; `about` says which bench run produced it."""
    kinds = []
    for kind, by_rate in table.items():
        rates = []
        for rate, rows in by_rate.items():
            lines = ",\n".join(f"      {json.dumps(list(row), ensure_ascii=False)}" for row in rows)
            rates.append(f'    "{int(rate)}": [\n{lines}\n    ]')
        kinds.append(f"  {json.dumps(kind)}: {{\n" + ",\n".join(rates) + "\n  }")
    body = ",\n".join(kinds)
    Path(path).write_text(
        f'{{\n "about": {json.dumps(about, ensure_ascii=False)},\n "recommendation": {{\n{body}\n }}\n}}\n',
        encoding="utf-8",
    )


#: kind → rate (Hz) → rows: the table `auto` uses.
RECOMMENDATION: Table = load_recommendation()


def scene_kind(scene: Scene, root: complex, substeps: int = 1) -> tuple[str, str]:
    """(kind, why) of a scene at its dt, given its fastest mode `root` (1/s) and the substeps
    it takes in contact (`contact_substeps`)."""
    z = abs(root) * scene.dt / substeps
    split = f" in {substeps} substeps while in contact" if substeps > 1 else ""
    if z > STIFF_MODE_DT:
        return "stiff", f"fastest mode |s|·dt = {z:.3g}{split} > {STIFF_MODE_DT:g}, not resolved by the step"
    events = [key for key, eff in EFFECTS.items() if (e := eff.build(scene)) is not None and not e.smooth]
    if events:
        stops = f", MCP stops at {list(scene.mcp_limits)} rad" if scene.mcp_limits is not None else ""
        return "stops", f"events of model.{', model.'.join(events)}{stops}{split}"
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


def pick(rows: Sequence[Sequence[object]], root: complex, dt: float, target: float = AUTO_TARGET) -> tuple[str, str]:
    """(method, why) from one row of the table, the rule auto and the bench report share.

    rows: (method, worst error rad, µs per step), cheapest first; root: the scene's fastest
    mode, 1/s; dt: s; target: rad. Of the stable methods within `target`, the most accurate among those
    costing at most COST_MARGIN × the cheapest one (on equal error the cheaper); else the most accurate
    stable one; else FALLBACK. Methods not in METHODS are ignored.
    """
    stable: list[Row] = []
    skipped: list[str] = []
    for raw in rows:
        row = Row(*raw)  # type: ignore[arg-type]
        cls = METHODS.get(row.method)
        if cls is None:
            continue
        if stable_at(cls, root, dt):
            stable.append(row)
        else:
            skipped.append(row.method)
    unstable = f"; unstable here: {', '.join(skipped)}" if skipped else ""
    within = [row for row in stable if row.error <= target]
    if within:
        cheapest = min(row.cost for row in within)
        best = min((row for row in within if row.cost <= COST_MARGIN * cheapest), key=lambda r: (r.error, r.cost))
        missed = "".join(f"; cheaper {r.method} missed it ({r.error:.1e} rad)" for r in stable
                         if r.cost < best.cost and r.error > target)
        close = "".join(f"; {r.method} as cheap within timing noise ({r.cost:.3g} µs/step) but less accurate ({r.error:.1e} rad)"
                        for r in within if r.cost < best.cost)
        return best.method, (
            f"the bench measured {best.method} as the cheapest method within {target:g} rad "
            f"(worst {best.error:.1e} rad, {best.cost:.0f} µs/step){close}{missed}{unstable}"
        )
    if stable:
        best = min(stable, key=lambda r: r.error)
        return best.method, (
            f"no stable method reached {target:g} rad in the bench: {best.method} is the most accurate "
            f"(worst {best.error:.1e} rad, {best.cost:.0f} µs/step){unstable}"
        )
    return FALLBACK, f"no tabulated method is stable{unstable}: {FALLBACK}, L-stable"


def contact_substeps(scene: Scene, implicit: bool = False) -> int:
    """Substeps m of a step in contact under `method: auto`: 1 without contact (no element with kinks).

    Explicit (`implicit` False): the fewest with |s|·dt/m ≤ CONTACT_SUBSTEP_MODE_DT on the scene's
    fastest mode s (its contact mode, at the contact element's design force); 1 when the scene is
    stiff without its contact too, or needs more than MAX_CONTACT_SUBSTEPS: then the whole run wants
    an implicit method. Implicit (FALLBACK): the fewest with ω_c·dt/m ≤ IMPLICIT_CONTACT_MODE_DT on
    the contact's oscillatory mode ω_c (`contact_frequency`), at most MAX_CONTACT_SUBSTEPS: the
    friction's damping, however fast, is left to the L-stable method."""
    system = scene.build_system()
    q0, _ = scene.initial_state()
    smooth = [e for e in system.elements if not has_kinks(e, q0)]
    if len(smooth) == len(system.elements):
        return 1  # no contact
    theta_range = mcp_range(scene)
    if implicit:
        kinks = [e for e in system.elements if e not in smooth]
        omega = contact_frequency(FingerSystem(scene.params, kinks), theta_range)
        return min(max(1, math.ceil(omega * scene.dt / IMPLICIT_CONTACT_MODE_DT)), MAX_CONTACT_SUBSTEPS)
    if abs(fastest_mode(FingerSystem(scene.params, smooth), theta_range)) * scene.dt > STIFF_MODE_DT:
        return 1
    m = math.ceil(abs(fastest_mode(system, theta_range)) * scene.dt / CONTACT_SUBSTEP_MODE_DT)
    return m if 1 <= m <= MAX_CONTACT_SUBSTEPS else 1


def contact_frequency(contact: FingerSystem, theta1_range: tuple[float, float]) -> float:
    """The contact's oscillatory mode ω_c = √(K_c/I) (rad/s), largest over the open poses θ1 in
    theta1_range (rad) of a system holding only the contact elements: |s₁ s₂| = K_c/I of its modal
    roots, whatever its damping (the Hunt–Crossley and friction terms only move the roots apart)."""
    lo, hi = kinematics.assembly_range(contact.params)
    lo, hi = max(theta1_range[0], lo + TOGGLE_MARGIN), min(theta1_range[1], hi - TOGGLE_MARGIN)
    worst = 0.0
    for i in range(SAMPLES):
        q = kinematics.assemble(contact.params, lo + (hi - lo) * i / (SAMPLES - 1))
        if not inside_object(contact, q):
            s1, s2 = modal_roots(contact, q)
            worst = max(worst, math.sqrt(abs(s1 * s2)))
    return worst


def choose_method(scene: Scene) -> tuple[str, str]:
    """(method, reason) for `method: auto`: the table's cheapest fixed-step method within
    scene.tolerance / TABLE_MARGIN on a scene without events that is not stiff; else ERROR_CONTROLLED
    at the scene's tolerance (`error_control`)."""
    system = scene.build_system()
    root = fastest_mode(system, mcp_range(scene))
    kind, why = scene_kind(scene, root)
    rows = RECOMMENDATION.get(kind, {})
    q0, _ = scene.initial_state()
    # contact (an element's kinks) shares the stops row's kind
    label = "contact" if kind == "stops" and any(has_kinks(e, q0) for e in system.elements) else kind
    if kind in ("smooth", "discontinuous") and rows:
        rate, rate_text = table_rate(list(rows), scene.dt)
        target = scene.tolerance / TABLE_MARGIN
        method, because = pick(rows[rate], root, scene.dt, target)
        if any(Row(*row).method == method and Row(*row).error <= target for row in rows[rate]):
            reason = f"{label} scene ({why}); at {rate_text} {because}"
            LOG.info("method auto → %s: %s", method, reason)
            return method, reason
    rtol, _ = error_control(scene.tolerance)
    reason = (f"{label} scene ({why}); error-controlled {ERROR_CONTROLLED} at rtol = atol = {rtol:.0e} for "
              f"{scene.tolerance:g} rad on θ, events located inside the step; the run reports its estimated error"
              + realtime_note(scene, root))
    LOG.info("method auto → %s: %s", ERROR_CONTROLLED, reason)
    return ERROR_CONTROLLED, reason


def realtime_note(scene: Scene, root: complex) -> str:
    """"" when ERROR_CONTROLLED is predicted to step `scene` in real time at 1/dt, else "; " and what it
    cannot do and what would: the internal steps per output step that its fastest mode `root` (1/s) forces
    (|s|·dt / DOP853_STABILITY, whatever the tolerance), their predicted CPU against REALTIME_SHARE of the period."""
    attempts = max(1.0, abs(root) * scene.dt / DOP853_STABILITY)
    events = any(not e.smooth for e in build_elements(scene))  # stops, contact: the event loop's cost
    cost = ATTEMPT_US * attempts + (EVENT_STEP_US if events else 0.0)
    budget = REALTIME_SHARE * scene.dt * 1e6
    if cost <= budget:
        return ""
    note = (f"; cannot hold {scene.tolerance:g} rad in real time at {1.0 / scene.dt:g} Hz: its fastest mode forces "
            f"about {attempts:.0f} internal steps per step, about {cost:.0f} µs of CPU against {budget:.0f} µs "
            f"(a looser tolerance does not help); a realtime_factor ≤ {budget / cost:.2g} holds it")
    LOG.warning("method auto → %s%s", ERROR_CONTROLLED, note)
    return note


def error_control(tolerance: float) -> tuple[float, float]:
    """(rtol, atol) of ERROR_CONTROLLED that deliver a global error of `tolerance` rad on θ."""
    tol = ERROR_CONTROL_PER_TOLERANCE * tolerance
    return tol, tol


def integrator_options(scene: Scene, method: str) -> dict[str, float]:
    """The keyword options of `method`'s integrator under `method: auto`: ERROR_CONTROLLED's
    tolerances from scene.tolerance; none for a fixed-step method."""
    if method != ERROR_CONTROLLED:
        return {}
    rtol, atol = error_control(scene.tolerance)
    return {"rtol": rtol, "atol": atol}


def radau_amplification(z: complex) -> float:
    """|R(z)| of the 3-stage Radau IIA method (order 5; Hairer & Wanner, *Solving ODEs II*, IV.3):
    the factor by which one step scales a mode y' = λy, z = λ·dt."""
    return abs((1 + 2 * z / 5 + z**2 / 20) / (1 - 3 * z / 5 + 3 * z**2 / 20 - z**3 / 60))


def warn_unresolved_contact(scene: Scene, method: type) -> str:
    """Warn (and return the warning, "" if none) when a hand-chosen implicit `method` does not resolve the
    scene's contact mode ω_c at dt (ω_c·dt > IMPLICIT_CONTACT_MODE_DT): its stable step damps the
    unresolved oscillation instead, an energy loss the physics does not have (radau at 1 ms on
    an elastic impact loses 1.3 % of the energy and ends 0.19 rad off)."""
    system = scene.build_system()
    q0, _ = scene.initial_state()
    kinks = [e for e in system.elements if not e.smooth and not all(e.impact(i) is not None for i in range(len(e.gaps(q0))))]
    if not kinks:
        return ""
    omega = contact_frequency(FingerSystem(scene.params, kinks), mcp_range(scene))
    z = omega * scene.dt
    if z <= IMPLICIT_CONTACT_MODE_DT:
        return ""
    loss = ""
    if method.name == FALLBACK:
        # a contact lasts about half a period of its mode, π/(ω_c·dt) steps; energy ∝ amplitude²
        kept = radau_amplification(1j * z) ** (2.0 * math.pi / z)
        loss = f", which takes {100.0 * (1.0 - kept):.2g} % of the energy out of every contact (|R(iω_c·dt)| = {radau_amplification(1j * z):.4f} per step)"
    text = (f"integrator.method {method.name} at dt = {scene.dt:g} s does not resolve the contact mode "
            f"(ω_c = {omega:.3g} rad/s, ω_c·dt = {z:.2g} > {IMPLICIT_CONTACT_MODE_DT:g}){loss}; "
            f"dt ≤ {IMPLICIT_CONTACT_MODE_DT / omega:.2g} s or method auto resolves it")
    LOG.warning(text)
    return text


def promise_note(scene: Scene, method: str, error_estimate: float) -> str:
    """A warning line when a run of `method: auto` estimates more error than scene.tolerance (rad), else ""."""
    if scene.method != AUTO or not math.isfinite(error_estimate) or error_estimate <= scene.tolerance:
        return ""
    return (f"warning: {method} estimates {error_estimate:.1e} rad of error on θ, more than integrator.tolerance "
            f"{scene.tolerance:g} rad; a smaller --tolerance tightens its error control")
