"""A grasp task: a scene, a script of setpoints and disturbances, and the limits that judge it.

Task files are YAML 1.2 in `config/tasks/` (read by `finger_sim.scene_yaml`, like scenes):

    name: hold_cup                      # default: the file's stem
    description: "..."
    scene: ../grasp_cylinder.yaml       # relative to the task file
    objects: [...]                      # optional: replaces the scene's objects (same schema)
    duration: 1.5                       # s (replaces the scene's)
    controller: {sample_steps: 1, delay_steps: 1}   # whole steps of the scene's dt
    setpoints: [{t: 0.0, value: 0.5}]   # the grip-force setpoint, N, from t on (s)
    disturbances:                       # optional: a tip force (N, model plane) over [start, end)
      - {type: tip_force, start: 1.0, end: 1.4, force: [0.0, -0.3]}
    hold_after: 0.4                     # s after each setpoint change: the holding window starts
    limits: {settle_time: 0.5, overshoot: 10.0, hold_rms: 0.01, crushed: false}

A number in `limits` is the largest value that passes (`finger_sim.tasks.metrics.METRICS`
names and units); a boolean is the value that passes. Times in the script are rounded to
the step grid (a change acts from the first step at or after its time).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from finger_sim.errors import ConfigError
from finger_sim.scene import NAME_LENGTH, Scene, load_scene, safe_name, scene_from_dict
from finger_sim.scene_yaml import mapping, number, pair, read_scene_file, text, whole
from finger_sim.tasks.metrics import BOOLEAN_METRICS, METRICS
from finger_sim.tip_force_profile import TipForceSpan, check_spans

_KEYS = {"name", "description", "scene", "objects", "duration", "controller", "setpoints", "disturbances",
         "hold_after", "limits"}
#: Longest task, s; and most setpoint changes and disturbances (a task is a short script).
MAX_DURATION = 600.0
MAX_EVENTS = 1000
#: The scene inputs a controller may command: a torque (N·m), or a drive scene's voltage (V).
INPUTS = ("torque", "voltage")
#: The default holding window: from this long after a setpoint change, s.
HOLD_AFTER = 0.4
#: Most steps of dt between controller samples, or of delay.
MAX_STEPS = 10**6
#: Largest grip-force setpoint and disturbance force, N.
MAX_FORCE = 1e3
#: Longest description and scene path, characters.
TEXT_LENGTH = 4096


@dataclass(frozen=True)
class Disturbance:
    """A constant tip force (N, model plane) over [start, end) s."""

    start: float
    end: float
    force: tuple[float, float]


@dataclass(frozen=True)
class Task:
    """A validated task: the scene to run (objects and duration applied) and its script."""

    name: str
    description: str
    scene: Scene
    sample_steps: int
    delay_steps: int
    setpoints: tuple[tuple[float, float], ...]  # (t s, value N), t increasing, the first at 0
    disturbances: tuple[Disturbance, ...]
    hold_after: float
    limits: dict[str, float | bool]
    input: str = "torque"


def load_task(path: str | Path) -> Task:
    """Read and validate a task file; ConfigError names the file and the key."""
    path = Path(path)
    try:
        data = read_scene_file(path)
    except ConfigError as exc:  # the reader names it a scene: this file is a task
        raise ConfigError(f"task file {path}", exc.allowed.replace("scene", "task"), exc.got) from None
    try:
        return task_from_dict({} if data is None else data, base=path.parent, default_name=safe_name(path.stem))
    except ConfigError as exc:
        raise exc.within(path.name) from None


def task_from_dict(data: Any, *, base: Path, default_name: str = "task") -> Task:
    """Validate a task mapping; `scene` paths are relative to `base`."""
    data = mapping(data, "task", _KEYS)
    name = text(data.get("name", default_name), "name", NAME_LENGTH)
    if "scene" not in data:
        raise ConfigError("scene", "the path of a scene file (relative to the task file)", None)
    scene_path = base / text(data["scene"], "scene", TEXT_LENGTH)
    try:
        scene = load_scene(scene_path)
    except ConfigError as exc:
        raise ConfigError(f"scene ({scene_path.name}): {exc.key}", exc.allowed, exc.got) from None
    scene_data = scene.to_dict()
    scene_data["name"] = name
    scene_data["duration"] = number(data.get("duration", scene.duration), "duration", minimum=0.0, maximum=MAX_DURATION, strict=True)
    if "objects" in data:
        scene_data["objects"] = data["objects"]
    scene = scene_from_dict(scene_data)
    ctrl = mapping(data.get("controller", {}), "controller", {"sample_steps", "delay_steps", "input"})
    sample_steps = _whole(ctrl.get("sample_steps", 1), "controller.sample_steps", 1)
    delay_steps = _whole(ctrl.get("delay_steps", 1), "controller.delay_steps", 0)
    scene_input = "torque" if scene.drive is None else "voltage"
    inp = ctrl.get("input", scene_input)
    if inp not in INPUTS:
        raise ConfigError("controller.input", f"one of {list(INPUTS)} (the scene input the controller commands)", inp)
    if inp != scene_input:
        raise ConfigError("controller.input", f"'{scene_input}', the input of the scene '{scene.name}'", inp)
    disturbances = _disturbances(data.get("disturbances", []), scene.duration)
    # the disturbances join the scene's own tip-force profile: the scene steps them (finger_sim.scene_changes)
    spans = [*scene.tip_force_profile, *(TipForceSpan(d.start, d.end, d.force) for d in disturbances)]
    scene = dataclasses.replace(scene, tip_force_profile=check_spans(spans, "disturbances"))
    return Task(
        name=name,
        description=text(data.get("description", ""), "description", TEXT_LENGTH),
        scene=scene,
        sample_steps=sample_steps,
        delay_steps=delay_steps,
        setpoints=_setpoints(data.get("setpoints"), scene.duration),
        disturbances=disturbances,
        hold_after=number(data.get("hold_after", HOLD_AFTER), "hold_after", minimum=0.0, maximum=MAX_DURATION),
        limits=_limits(data.get("limits", {})),
        input=inp,
    )


def _whole(value: Any, key: str, low: int) -> int:
    return whole(value, key, low, MAX_STEPS, f"a whole number of steps in [{low}, {MAX_STEPS}]")


def _list(value: Any, key: str) -> list[Any]:
    if not isinstance(value, list) or len(value) > MAX_EVENTS:
        raise ConfigError(key, f"a list of at most {MAX_EVENTS} entries", value)
    return value


def _setpoints(value: Any, duration: float) -> tuple[tuple[float, float], ...]:
    items = _list(value, "setpoints")
    if not items:
        raise ConfigError("setpoints", "at least one {t, value}, the first at t = 0", value)
    out: list[tuple[float, float]] = []
    for i, item in enumerate(items):
        item = mapping(item, f"setpoints[{i}]", {"t", "value"})
        t = number(item.get("t"), f"setpoints[{i}].t", minimum=0.0, maximum=duration)
        v = number(item.get("value"), f"setpoints[{i}].value", minimum=0.0, maximum=MAX_FORCE)
        if (i == 0 and t != 0.0) or (out and t <= out[-1][0]):
            raise ConfigError(f"setpoints[{i}].t", "times increasing from 0 (s)", t)
        out.append((t, v))
    return tuple(out)


def _disturbances(value: Any, duration: float) -> tuple[Disturbance, ...]:
    out = []
    for i, item in enumerate(_list(value, "disturbances")):
        where = f"disturbances[{i}]"
        item = mapping(item, where, {"type", "start", "end", "force"})
        if item.get("type") != "tip_force":
            raise ConfigError(f"{where}.type", "tip_force (a pull on the fingertip)", item.get("type"))
        start = number(item.get("start"), f"{where}.start", minimum=0.0, maximum=duration)
        end = number(item.get("end", duration), f"{where}.end", minimum=start, maximum=duration, strict=True)
        out.append(Disturbance(start, end, pair(item.get("force"), f"{where}.force", MAX_FORCE)))
    spans = sorted(out, key=lambda d: d.start)
    for a, b in zip(spans, spans[1:]):
        if b.start < a.end:
            raise ConfigError("disturbances", "tip-force spans that do not overlap", f"[{a.start}, {a.end}) and [{b.start}, {b.end})")
    return tuple(spans)


def _limits(value: Any) -> dict[str, float | bool]:
    limits = mapping(value, "limits", set(METRICS))
    out: dict[str, float | bool] = {}
    for key, limit in limits.items():
        if key in BOOLEAN_METRICS:
            if not isinstance(limit, bool):
                raise ConfigError(f"limits.{key}", "true or false (the value that passes)", limit)
            out[key] = limit
        else:
            out[key] = number(limit, f"limits.{key}", minimum=0.0, maximum=math.inf)
    return out
