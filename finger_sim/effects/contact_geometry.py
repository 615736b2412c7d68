"""What a scene says about contact (spec §7): its objects, the contact law's parameters and
the phalanx radii, validated with errors that name the key.

Objects are fixed in the model plane (m, origin at the MCP pivot A, spec §1). A *circle* is a
cylinder whose axis is normal to the plane; a *plane* is a half-plane through `point` with
outward unit `normal`, the object on the side of −normal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from finger_sim.errors import ConfigError

Vec2 = tuple[float, float]

#: Phalanx capsule radii ρ1 (proximal, A→B) and ρ3 (distal, B→tip), m (spec §7 assumption).
PHALANX_RADII: Vec2 = (0.008, 0.007)
#: A plane normal shorter than this (in the scene's units, m) has no direction.
MIN_NORMAL_NORM = 1e-9
#: Most normalization passes of a plane's normal; a fixed point is reached within 3.
NORMALIZE_PASSES = 8

OBJECT_TYPES = ("circle", "plane")
_OBJECT_KEYS = {"circle": {"name", "type", "center", "radius"}, "plane": {"name", "type", "point", "normal"}}
#: Optional keys of every object (`ObjectProperties`): its own contact law and its strength.
_PROPERTY_KEYS = ("stiffness", "damping", "break_force")
#: The kinds of prescribed motion and their keys (besides `type`), `ObjectMotion`.
_MOTION_KEYS = {"push": {"direction", "distance", "start", "duration"},
                "vibration": {"direction", "amplitude", "frequency", "start"}}
#: Bounds of a prescribed motion: its distance or amplitude (m), frequency (Hz), times (s).
MAX_MOTION_EXTENT = 1.0
MAX_MOTION_FREQUENCY = 1e3
MAX_MOTION_TIME = 1e6


@dataclass(frozen=True)
class ObjectMotion:
    """A prescribed motion of an object in the model plane: its offset from its place in the
    scene, c(t) = c + s(t) u (m), u the unit `direction`, s(t) ≥ 0 (m) smooth in velocity:

    - push: s = L (1 − cos(π (t − t0) / T)) / 2 over [t0, t0 + T], 0 before, L after: moved
      by L = `distance` in T = `duration` s from t0 = `start` (a pull is a push away);
    - vibration: s = A (1 − cos(2π f (t − t0))) / 2 from t0 on, 0 before: back and forth over
      A = `amplitude` m at f = `frequency` Hz.

    s and s' are continuous (no velocity jump of the object); s'' jumps at the ends of a push
    and at the start of a vibration, which a step straddles with a local error of order dt³.
    """

    kind: str
    direction: tuple[float, float]
    extent: float  # L or A, m
    start: float  # t0, s
    rate: float  # 1/T (push) or f (vibration), 1/s

    def offset(self, t: float) -> tuple[float, float]:
        """c(t) − c, m."""
        s = self._s(t)
        return (s * self.direction[0], s * self.direction[1])

    def velocity(self, t: float) -> tuple[float, float]:
        """ċ(t), m/s."""
        x = t - self.start
        if x <= 0.0 or (self.kind == "push" and x * self.rate >= 1.0):
            return (0.0, 0.0)
        w = math.pi * self.rate * (1.0 if self.kind == "push" else 2.0)
        ds = 0.5 * self.extent * w * math.sin(w * x)
        return (ds * self.direction[0], ds * self.direction[1])

    def _s(self, t: float) -> float:
        x = t - self.start
        if x <= 0.0:
            return 0.0
        if self.kind == "push":
            return self.extent if x * self.rate >= 1.0 else 0.5 * self.extent * (1.0 - math.cos(math.pi * self.rate * x))
        return 0.5 * self.extent * (1.0 - math.cos(2.0 * math.pi * self.rate * x))

    def to_dict(self) -> dict[str, Any]:
        """The motion in the scene schema."""
        if self.kind == "push":
            return {"type": "push", "direction": list(self.direction), "distance": self.extent, "start": self.start,
                    "duration": 1.0 / self.rate}
        return {"type": "vibration", "direction": list(self.direction), "amplitude": self.extent,
                "frequency": self.rate, "start": self.start}


def motion_from_dict(value: Any) -> ObjectMotion:
    """Validate an object's `motion:` mapping (keys named relative to it, e.g. `motion.distance`)."""
    if not isinstance(value, dict):
        raise ConfigError("motion", "a mapping {type: push|vibration, direction, ...}", value)
    kind = value.get("type")
    if kind not in _MOTION_KEYS:
        raise ConfigError("motion.type", f"one of {sorted(_MOTION_KEYS)}", kind)
    allowed = _MOTION_KEYS[kind]
    unknown = sorted(set(value) - allowed - {"type"}, key=str)
    if unknown:
        raise ConfigError("motion", f"only the keys {sorted(allowed | {'type'})} for a {kind}", unknown[0])
    missing = sorted(allowed - set(value))
    if missing:
        raise ConfigError(f"motion.{missing[0]}", f"a value (required for a {kind})", None)
    nx, ny = _vec2(value["direction"], "motion.direction")
    norm = math.hypot(nx, ny)
    if norm < MIN_NORMAL_NORM:
        raise ConfigError("motion.direction", "a non-zero direction (it is normalized)", list(value["direction"]))

    def bounded(key: str, high: float) -> float:
        x = value[key]
        if not (_is_number(x) and 0.0 < x <= high) and not (key == "start" and _is_number(x) and 0.0 <= x <= high):
            raise ConfigError(f"motion.{key}", f"a finite number in (0, {high:g}]" if key != "start" else f"a time in [0, {high:g}] s", x)
        return float(x)

    start = bounded("start", MAX_MOTION_TIME)
    if kind == "push":
        return ObjectMotion(kind, (nx / norm, ny / norm), bounded("distance", MAX_MOTION_EXTENT), start,
                            1.0 / bounded("duration", MAX_MOTION_TIME))
    return ObjectMotion(kind, (nx / norm, ny / norm), bounded("amplitude", MAX_MOTION_EXTENT), start,
                        bounded("frequency", MAX_MOTION_FREQUENCY))


@dataclass(frozen=True)
class ObjectProperties:
    """What an object adds to the scene's contact law: its own stiffness k_c (N/m^e) and
    Hunt–Crossley damping d_c (s/m), None = `model.contact`'s; the normal force (N, the
    sum over the phalanges) beyond which it is crushed, None = unbreakable; and its prescribed
    motion in the model plane, None = fixed in finger_base.

    Crushing is judged by whoever steps the scene (`finger_sim.grasp_objects`): the force law
    itself does not change until the crushed object is taken out of the scene.
    """

    stiffness: float | None = None
    damping: float | None = None
    break_force: float | None = None
    motion: ObjectMotion | None = None  # None: fixed in finger_base

    def __post_init__(self) -> None:
        for name, low, strict in (("stiffness", 0.0, True), ("damping", 0.0, False), ("break_force", 0.0, True)):
            value = getattr(self, name)
            if value is None:
                continue
            if not _is_number(value) or value < low or (strict and value == low):
                raise ConfigError(name, f"a finite number {'>' if strict else '≥'} {low:g}", value)
            object.__setattr__(self, name, float(value))

    def to_dict(self) -> dict[str, Any]:
        """The keys that are set, as in the scene schema."""
        out: dict[str, Any] = {name: getattr(self, name) for name in _PROPERTY_KEYS if getattr(self, name) is not None}
        if self.motion is not None:
            out["motion"] = self.motion.to_dict()
        return out


@dataclass(frozen=True)
class Circle:
    """A cylinder normal to the model plane: centre (m, model plane) and radius R > 0 (m)."""

    name: str
    center: Vec2
    radius: float
    properties: ObjectProperties = ObjectProperties()

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "center", _vec2(self.center, "center"))
        if not (_is_number(self.radius) and self.radius > 0.0):
            raise ConfigError("radius", "a finite radius > 0 (m)", self.radius)
        object.__setattr__(self, "radius", float(self.radius))


@dataclass(frozen=True)
class Plane:
    """A half-plane through `point` (m) with outward unit `normal`; the object lies on the side of −normal.

    A non-unit normal is normalized (its direction is what it means); a zero one is refused.
    """

    name: str
    point: Vec2
    normal: Vec2
    properties: ObjectProperties = ObjectProperties()

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "point", _vec2(self.point, "point"))
        nx, ny = _vec2(self.normal, "normal")
        norm = math.hypot(nx, ny)
        if norm < MIN_NORMAL_NORM:
            raise ConfigError("normal", f"a non-zero direction (|n| ≥ {MIN_NORMAL_NORM:g}; it is normalized)", list(self.normal))
        # Normalize to a fixed point (2–3 passes): a stored normal then reads back bit for bit,
        # so a logged scene re-simulates exactly.
        for _ in range(NORMALIZE_PASSES):
            unit = (nx / norm, ny / norm)
            if unit == (nx, ny):
                break
            (nx, ny), norm = unit, math.hypot(*unit)
        object.__setattr__(self, "normal", (nx, ny))


SceneObject = Circle | Plane


@dataclass(frozen=True)
class ContactParams:
    """The contact law of spec §7: F_n = max(0, k δ^e (1 + d δ')), F_t = −μ F_n tanh(v_t / v_s)."""

    stiffness: float = 1.0e5  # k_c, N/m^e
    exponent: float = 1.5  # e, ≥ 1 (below 1 the stiffness k e δ^(e−1) is infinite at onset)
    damping: float = 1.5  # d_c, s/m (Hunt–Crossley)
    friction: float = 0.0  # μ, Coulomb coefficient
    slip_velocity: float = 1.0e-3  # v_s, m/s, regularization of the Coulomb law

    def __post_init__(self) -> None:
        minima = {"stiffness": (0.0, True), "exponent": (1.0, False), "damping": (0.0, False), "friction": (0.0, False), "slip_velocity": (0.0, True)}
        for f in fields(self):
            value = getattr(self, f.name)
            low, strict = minima[f.name]
            if not _is_number(value) or value < low or (strict and value == low):
                raise ConfigError(f"model.contact.{f.name}", f"a finite number {'>' if strict else '≥'} {low:g}", value)
            object.__setattr__(self, f.name, float(value))


def objects_from_list(value: Any, key: str = "objects") -> tuple[SceneObject, ...]:
    """Validate a scene's `objects:` list (None or [] = no objects) into Circle and Plane objects.

    ConfigError names the offending key, e.g. `objects[1].radius`.
    """
    if value is None:
        return ()
    if not isinstance(value, list):
        raise ConfigError(key, "a list of objects ({name, type: circle|plane, ...})", value)
    out: list[SceneObject] = []
    names: set[str] = set()
    for i, item in enumerate(value):
        where = f"{key}[{i}]"
        if not isinstance(item, dict):
            raise ConfigError(where, "a mapping {name, type, ...}", item)
        kind = item.get("type")
        if kind not in OBJECT_TYPES:
            raise ConfigError(f"{where}.type", f"one of {list(OBJECT_TYPES)}", kind)
        required = _OBJECT_KEYS[kind]
        allowed = required | set(_PROPERTY_KEYS) | {"motion"}
        unknown = sorted(set(item) - allowed, key=str)
        if unknown:
            raise ConfigError(where, f"only the keys {sorted(allowed)} for a {kind}", unknown[0])
        missing = sorted(required - set(item))
        if missing:
            raise ConfigError(f"{where}.{missing[0]}", f"a value (required for a {kind})", None)
        try:
            motion = motion_from_dict(item["motion"]) if "motion" in item else None
            props = ObjectProperties(**{k: item[k] for k in _PROPERTY_KEYS if k in item}, motion=motion)
            obj: SceneObject = (
                Circle(item["name"], item["center"], item["radius"], props)
                if kind == "circle"
                else Plane(item["name"], item["point"], item["normal"], props)
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}.{exc.key}", exc.allowed, exc.got) from None
        if obj.name in names:
            raise ConfigError(f"{where}.name", "a name no other object uses", obj.name)
        names.add(obj.name)
        out.append(obj)
    return tuple(out)


def contact_params_from_dict(value: Any, key: str = "model.contact", also: tuple[str, ...] = ()) -> ContactParams:
    """Validate `model.contact` (None = the spec's defaults); keys as in ContactParams. `also`: the keys of the
    same mapping that the caller has taken out and reads itself (named with the allowed keys in an error)."""
    if value is None:
        return ContactParams()
    allowed = {f.name for f in fields(ContactParams)}
    if not isinstance(value, dict):
        raise ConfigError(key, f"a mapping with the keys {sorted(allowed | set(also))}", value)
    unknown = sorted(set(value) - allowed, key=str)  # YAML keys may be ints, None, ...: sorted as text
    if unknown:
        raise ConfigError(key, f"only the keys {sorted(allowed | set(also))}", unknown[0])
    try:
        return ContactParams(**value)
    except ConfigError as exc:
        raise ConfigError(exc.key.replace("model.contact", key, 1), exc.allowed, exc.got) from None


def phalanx_radii_from_value(value: Any, key: str = "model.phalanx_radius") -> Vec2:
    """Validate `model.phalanx_radius` = [ρ1, ρ3], m, both > 0 (None = the spec's defaults)."""
    if value is None:
        return PHALANX_RADII
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(key, "[proximal, distal] capsule radii (m)", value)
    for i, r in enumerate(value):
        if not (_is_number(r) and r > 0.0):
            raise ConfigError(f"{key}[{i}]", "a finite radius > 0 (m)", r)
    return (float(value[0]), float(value[1]))


def _is_number(value: Any) -> bool:
    """A finite int or float; not a bool (YAML's `true` is an int to Python, not a length)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_name(name: Any) -> None:
    if not isinstance(name, str) or not name:
        raise ConfigError("name", "a non-empty string", name)


def _vec2(value: Any, key: str) -> Vec2:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(key, "a list of two numbers (m)", value)
    for i, x in enumerate(value):
        if not _is_number(x):
            raise ConfigError(f"{key}[{i}]", "a finite number (m)", x)
    return (float(value[0]), float(value[1]))
