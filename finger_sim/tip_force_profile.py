"""The tip-force profile of a scene (scene key `input.tip_force`): constant fingertip forces over spans of time.

Over each span [start, end) s the fingertip force is the span's instead of `model.tip_force`. A
span acts from the first step at or after its start to the first step at or after its end
(`first_step`); a span starting where another ends wins that step. The force is constant within a
step: `finger_sim.scene_changes.SceneChanges` switches the Simulator's scene at step boundaries.
Paths that run a scene as one fixed system (simulate, batch, sweep, rollout) refuse a profile
(`refuse_profile`) rather than ignore it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from finger_sim.errors import ConfigError
from finger_sim.inputs import BREAK_EPS
from finger_sim.scene_yaml import mapping, number, pair

if TYPE_CHECKING:  # scene.py reads its profile with this module
    from finger_sim.scene import Scene

#: Most spans of a tip-force profile (a scene is a short script).
MAX_SPANS = 1000
#: Largest tip force of a span, N (as model.tip_force).
MAX_SPAN_FORCE = 1e3


@dataclass(frozen=True)
class TipForceSpan:
    """A constant fingertip force `force` (N, model plane) over [start, end) s."""

    start: float
    end: float
    force: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {"start": self.start, "end": self.end, "force": list(self.force)}


def first_step(t: float, dt: float) -> int:
    """The first step index k with k·dt ≥ t (a time within BREAK_EPS·dt of a step counts as on it)."""
    return max(0, math.ceil(t / dt - BREAK_EPS))


def spans_from_list(value: Any, duration: float, key: str = "input.tip_force") -> tuple[TipForceSpan, ...]:
    """Validate a list of {start, end, force} (s, s, [N, N]); ConfigError names the entry and key."""
    if not isinstance(value, list) or len(value) > MAX_SPANS:
        raise ConfigError(key, f"a list of at most {MAX_SPANS} spans {{start, end, force}} (s, s, [N, N])", value)
    spans = []
    for i, item in enumerate(value):
        where = f"{key}[{i}]"
        item = mapping(item, where, {"start", "end", "force"})
        start = number(item.get("start"), f"{where}.start", minimum=0.0, maximum=duration)
        end = number(item.get("end", duration), f"{where}.end", minimum=start, maximum=duration, strict=True)
        spans.append(TipForceSpan(start, end, pair(item.get("force"), f"{where}.force", MAX_SPAN_FORCE)))
    return check_spans(spans, key)


def check_spans(spans: list[TipForceSpan], key: str) -> tuple[TipForceSpan, ...]:
    """The spans sorted by start; ConfigError if two overlap."""
    ordered = sorted(spans, key=lambda s: s.start)
    for a, b in zip(ordered, ordered[1:]):
        if b.start < a.end:
            raise ConfigError(key, "tip-force spans that do not overlap", f"[{a.start}, {a.end}) and [{b.start}, {b.end})")
    return tuple(ordered)


def tip_force_switches(scene: Scene) -> dict[int, tuple[float, float]]:
    """{step k: the tip force from step k on} of the scene's profile (empty without one)."""
    switches: dict[int, tuple[float, float]] = {}
    for span in scene.tip_force_profile:
        switches[first_step(span.end, scene.dt)] = scene.tip_force
    for span in scene.tip_force_profile:  # a span starting where another ends wins the step
        switches[first_step(span.start, scene.dt)] = span.force
    return switches


def static_scene(scene: Scene) -> Scene:
    """`scene` as one fixed system: its profile taken out, the tip force in force at step 0."""
    if not scene.tip_force_profile:
        return scene
    force = tip_force_switches(scene).get(0, scene.tip_force)
    return dataclasses.replace(scene, tip_force=force, tip_force_profile=())


def refuse_profile(scene: Scene, path: str) -> None:
    """ConfigError for a scene with a tip-force profile on a path that runs one fixed system."""
    if scene.tip_force_profile:
        raise ConfigError("input.tip_force", f"no tip-force profile with {path} (finger_node, resim and "
                          "`finger-sim tasks` step it; use the constant model.tip_force here)",
                          [s.to_dict() for s in scene.tip_force_profile])
