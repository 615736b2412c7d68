"""`method: auto`: pick the integrator from the scene's active effects and its dt, as the bench measured.

Three steps, each stated in the reason `choose_method` returns (and logs):

1. The scene's kind, from its active effects: *stiff* when the fastest mode of its force
   elements (`stability.fastest_mode`) is not resolved by dt (|s|·dt > STIFF_MODE_DT);
   else *stops* when an element has events (`smooth` is False: stops, contact); else
   *discontinuous* when its torque switches (`Profile.breakpoints`); else *smooth*.
2. The rate: the tabulated rate at or below 1/dt (accuracy measured at an equal or larger
   step, so no better than what the scene gets), or the slowest one below all of them.
3. `pick`: the cheapest method of the table's row whose worst error over the kind's bench
   scenes was within AUTO_TARGET, among those stable on the scene's fastest mode at its dt
   (`stability.stable_at`); if none reached the target, the most accurate stable one; if
   none is stable, FALLBACK (L-stable). The bench report calls the same `pick`.

Contact (spec §7) adds a mode of 10²–10⁴ rad/s that exists only while a phalanx touches an
object. Rather than an implicit method for the whole run, auto steps such a scene with the table's
explicit choice and `contact_substeps` divides each step that is in contact (or closes a contact
gap within it) into m equal substeps, m sized by the contact mode (CONTACT_SUBSTEP_MODE_DT):
the Simulator already splits steps at contact onset and release, so the free flight keeps the
plain step. Measured on grasp_impact and grasp_rigid at dt = 1 ms against a DOP853 solve at
rtol 1e-12 restarted at the events (README "Grasping"): radau costs 10–30× the free step there,
the substepped explicit step about 1–2×.

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
from finger_sim.effects import EFFECTS
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene
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


def pick(rows: Sequence[Sequence[object]], root: complex, dt: float) -> tuple[str, str]:
    """(method, why) from one row of the table, the rule auto and the bench report share.

    rows: (method, worst error rad, µs per step), cheapest first; root: the scene's fastest
    mode, 1/s; dt: s. The cheapest method within AUTO_TARGET that is stable at dt; else the
    most accurate stable one; else FALLBACK. Methods not in METHODS are ignored.
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
    within = [row for row in stable if row.error <= AUTO_TARGET]
    if within:
        best = within[0]
        missed = "".join(f"; cheaper {r.method} missed it ({r.error:.1e} rad)" for r in stable if r.cost < best.cost)
        return best.method, (
            f"the bench measured {best.method} as the cheapest method within {AUTO_TARGET:g} rad "
            f"(worst {best.error:.1e} rad, {best.cost:.0f} µs/step){missed}{unstable}"
        )
    if stable:
        best = min(stable, key=lambda r: r.error)
        return best.method, (
            f"no stable method reached {AUTO_TARGET:g} rad in the bench: {best.method} is the most accurate "
            f"(worst {best.error:.1e} rad, {best.cost:.0f} µs/step){unstable}"
        )
    return FALLBACK, f"no tabulated method is stable{unstable}: {FALLBACK}, L-stable"


def contact_substeps(scene: Scene, implicit: bool = False) -> int:
    """Substeps m of a step in contact under `method: auto`: 1 without objects.

    Explicit (`implicit` False): the fewest with |s|·dt/m ≤ CONTACT_SUBSTEP_MODE_DT on the scene's
    fastest mode s (its contact mode, at the contact element's design force); 1 when the scene is
    stiff without its contact too, or needs more than MAX_CONTACT_SUBSTEPS: then the whole run wants
    an implicit method. Implicit (FALLBACK): the fewest with ω_c·dt/m ≤ IMPLICIT_CONTACT_MODE_DT on
    the contact's oscillatory mode ω_c (`contact_frequency`), at most MAX_CONTACT_SUBSTEPS: the
    friction's damping, however fast, is left to the L-stable method."""
    system = scene.build_system()
    q0, _ = scene.initial_state()
    smooth = [e for e in system.elements if e.smooth or all(e.impact(i) is not None for i in range(len(e.gaps(q0))))]
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
    """(method, reason) for `method: auto`: the table's cheapest method within AUTO_TARGET that is stable
    at its step (dt, or dt/m in contact: `contact_substeps`)."""
    root = fastest_mode(scene.build_system(), mcp_range(scene))
    substeps = contact_substeps(scene)
    kind, why = scene_kind(scene, root, substeps)
    rows = RECOMMENDATION.get(kind, {})
    if not rows:
        return FALLBACK, f"{kind} scene ({why}); no measurements for it: {FALLBACK}, stable at every dt"
    rate, rate_text = table_rate(list(rows), scene.dt)
    method, because = pick(rows[rate], root, scene.dt / substeps)
    label = "contact" if kind == "stops" and scene.objects else kind  # a contact scene uses the bench's stops row
    row = f", the bench's '{kind}' row" if label != kind else ""
    reason = f"{label} scene ({why}{row}); at {rate_text} {because}"
    LOG.info("method auto → %s: %s", method, reason)
    return method, reason
