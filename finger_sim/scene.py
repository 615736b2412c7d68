"""Scenes: YAML files that say what a run models, and nothing more.

Schema (every key optional; omitted = the spec's default):

    name: paper_flexion          # default: the file's stem
    description: "..."
    model:
      spring_stiffness: 0.001    # N·m/rad, PIP spring (0 removes it)
      damping: 0.0               # N·m·s/rad at each joint
      gravity: [0.0, 0.0]        # m/s², model plane (X, Y)
      tip_force: [0.0, 0.0]      # N, constant, at the fingertip
      joint_limits: {mcp: [0.0, 1.5708]}   # rad; omit for no stops
      restitution: 0.0           # of the joint stops, in [0, 1]
      geometry: {r1: 0.046, ...} # FingerParams overrides (m, kg, rad)
    input:
      torque: {type: ramp, offset: 0.001, slope: 0.01}   # N·m, see finger_sim.inputs
    initial: {theta1: 0.0, theta1_dot: 0.0}             # rad, rad/s
    duration: 0.3                # s
    integrator: {method: rk4, dt: 0.001}                # method: a name in METHODS, or auto

Only the effects a scene turns on become force elements, so an absent effect costs
nothing per step.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from finger_sim import kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError
from finger_sim.forces import ForceElement, Gravity, JointDamping, PipSpring, TipForce
from finger_sim.inputs import Profile, Ramp, profile_from_dict
from finger_sim.integrators import METHODS
from finger_sim.model import FingerParams

AUTO = "auto"
_TOP_KEYS = {"name", "description", "model", "input", "initial", "duration", "integrator"}
_MODEL_KEYS = {"spring_stiffness", "damping", "gravity", "tip_force", "joint_limits", "restitution", "geometry"}


@dataclass(frozen=True)
class Scene:
    """A fully resolved scene: every default filled in, SI units."""

    name: str = "scene"
    description: str = ""
    params: FingerParams = field(default_factory=FingerParams)
    spring_stiffness: float = 0.001
    damping: float = 0.0
    gravity: tuple[float, float] = (0.0, 0.0)
    tip_force: tuple[float, float] = (0.0, 0.0)
    mcp_limits: tuple[float, float] | None = None
    restitution: float = 0.0
    torque: Profile = field(default_factory=lambda: Ramp(offset=0.001, slope=0.01))
    theta1: float = 0.0
    theta1_dot: float = 0.0
    duration: float = 0.3
    method: str = "rk4"
    dt: float = 0.001

    def force_elements(self) -> list[ForceElement]:
        """The active effects only."""
        alpha = kinematics.distal_offset(self.params)
        elements: list[ForceElement] = []
        if self.spring_stiffness:
            elements.append(PipSpring(self.spring_stiffness, alpha))
        if self.damping:
            elements.append(JointDamping(self.damping))
        if any(self.gravity):
            elements.append(Gravity(*self.gravity, self.params, alpha))
        if any(self.tip_force):
            elements.append(TipForce(*self.tip_force, self.params, alpha))
        return elements

    def build_system(self) -> FingerSystem:
        return FingerSystem(self.params, self.force_elements())

    def initial_state(self) -> tuple[kinematics.Vec3, kinematics.Vec3]:
        """(q, q') at t = 0 on the spec's branch; ConfigError if θ1 cannot be assembled."""
        q = kinematics.assemble(self.params, self.theta1)
        return q, kinematics.dependent_rates(self.params, q, self.theta1_dot)

    def to_dict(self) -> dict[str, Any]:
        """The resolved scene in the YAML schema (round-trips through `scene_from_dict`)."""
        model: dict[str, Any] = {
            "spring_stiffness": self.spring_stiffness,
            "damping": self.damping,
            "gravity": list(self.gravity),
            "tip_force": list(self.tip_force),
            "restitution": self.restitution,
            "geometry": asdict(self.params),
        }
        if self.mcp_limits is not None:
            model["joint_limits"] = {"mcp": list(self.mcp_limits)}
        return {
            "name": self.name,
            "description": self.description,
            "model": model,
            "input": {"torque": self.torque.to_dict()},
            "initial": {"theta1": self.theta1, "theta1_dot": self.theta1_dot},
            "duration": self.duration,
            "integrator": {"method": self.method, "dt": self.dt},
        }

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    def with_overrides(self, *, method: str | None = None, dt: float | None = None, duration: float | None = None) -> Scene:
        """A copy with command-line overrides, validated like the file's values."""
        data = self.to_dict()
        if method is not None:
            data["integrator"]["method"] = method
        if dt is not None:
            data["integrator"]["dt"] = dt
        if duration is not None:
            data["duration"] = duration
        return scene_from_dict(data)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; ConfigError names the file, key, allowed values and value."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError("scene", "a readable scene file", f"{path} ({exc.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError("scene", "valid YAML", f"{path}: {exc}") from None
    if data is None:
        data = {}
    try:
        return scene_from_dict(data, default_name=path.stem)
    except ConfigError as exc:
        raise ConfigError(f"{path.name}: {exc.key}", exc.allowed, exc.got) from None


def scene_from_dict(data: Any, *, default_name: str = "scene") -> Scene:
    """Validate a scene mapping (as loaded from YAML) into a Scene."""
    data = _mapping(data, "scene", _TOP_KEYS)
    model = _mapping(data.get("model", {}), "model", _MODEL_KEYS)
    geometry = _mapping(model.get("geometry", {}), "model.geometry", {f.name for f in fields(FingerParams)})
    params = FingerParams(**{k: _number(v, f"model.geometry.{k}") for k, v in geometry.items()})
    inp = _mapping(data.get("input", {}), "input", {"torque"})
    initial = _mapping(data.get("initial", {}), "initial", {"theta1", "theta1_dot"})
    integ = _mapping(data.get("integrator", {}), "integrator", {"method", "dt"})
    method = integ.get("method", Scene.method)
    if method not in METHODS and method != AUTO:
        raise ConfigError("integrator.method", f"one of {sorted(METHODS) + [AUTO]}", method)
    limits = _mapping(model.get("joint_limits", {}), "model.joint_limits", {"mcp"})
    mcp = None
    if "mcp" in limits:
        mcp = _pair(limits["mcp"], "model.joint_limits.mcp")
        if not mcp[0] < mcp[1]:
            raise ConfigError("model.joint_limits.mcp", "[lower, upper] with lower < upper (rad)", list(mcp))
        lo, hi = kinematics.assembly_range(params)
        if not (lo < mcp[0] and mcp[1] < hi):
            raise ConfigError("model.joint_limits.mcp", f"limits inside the assemblable range ({lo:.6f}, {hi:.6f}) rad", list(mcp))
    scene = Scene(
        name=str(data.get("name", default_name)),
        description=str(data.get("description", "")),
        params=params,
        spring_stiffness=_number(model.get("spring_stiffness", Scene.spring_stiffness), "model.spring_stiffness", minimum=0.0),
        damping=_number(model.get("damping", Scene.damping), "model.damping", minimum=0.0),
        gravity=_pair(model.get("gravity", [0.0, 0.0]), "model.gravity"),
        tip_force=_pair(model.get("tip_force", [0.0, 0.0]), "model.tip_force"),
        mcp_limits=mcp,
        restitution=_number(model.get("restitution", Scene.restitution), "model.restitution", minimum=0.0, maximum=1.0),
        torque=profile_from_dict(inp["torque"]) if "torque" in inp else Ramp(offset=0.001, slope=0.01),
        theta1=_number(initial.get("theta1", Scene.theta1), "initial.theta1"),
        theta1_dot=_number(initial.get("theta1_dot", Scene.theta1_dot), "initial.theta1_dot"),
        duration=_number(data.get("duration", Scene.duration), "duration", minimum=0.0, strict=True),
        method=method,
        dt=_number(integ.get("dt", Scene.dt), "integrator.dt", minimum=0.0, strict=True),
    )
    scene.initial_state()  # refuses a θ1 outside the assemblable range, or at a toggle
    if mcp is not None and not (mcp[0] <= scene.theta1 <= mcp[1]):
        raise ConfigError("initial.theta1", f"an angle within model.joint_limits.mcp {list(mcp)} rad", scene.theta1)
    if scene.dt > scene.duration:
        raise ConfigError("integrator.dt", f"a step no longer than duration ({scene.duration} s)", scene.dt)
    return scene


def _mapping(value: Any, key: str, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(key, "a mapping", value)
    unknown = sorted(set(value) - allowed)
    if unknown:
        raise ConfigError(key, f"only the keys {sorted(allowed)}", unknown[0])
    return value


def _number(value: Any, key: str, *, minimum: float | None = None, maximum: float | None = None, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(key, "a finite number", value)
    if minimum is not None and (value < minimum or (strict and value == minimum)):
        raise ConfigError(key, f"a number {'>' if strict else '≥'} {minimum:g}" + (f" and ≤ {maximum:g}" if maximum is not None else ""), value)
    if maximum is not None and value > maximum:
        raise ConfigError(key, f"a number ≥ {minimum:g} and ≤ {maximum:g}", value)
    return float(value)


def _pair(value: Any, key: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(key, "a list of two numbers", value)
    return (_number(value[0], f"{key}[0]"), _number(value[1], f"{key}[1]"))

