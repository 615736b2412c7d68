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
      phalanx_radius: [0.008, 0.007]   # m: proximal, distal capsule radii (spec §7)
      contact: {stiffness: 1.0e5, exponent: 1.5, damping: 1.5, friction: 0.0, slip_velocity: 1.0e-3}
      # contact may add friction_model: stick_slip (exact stick and slip, μ_k = friction), static_friction
      # (μ_s ≥ μ_k, default μ_k) and stribeck_velocity (m/s, optional): finger_sim.effects.friction_modes
      drive: {}                  # a DC motor and gear train (spec §8; {} = its defaults), see finger_sim.actuators
    objects:                     # omitted or empty = no contact element, no cost (spec §7)
      - {name: cup, type: circle, center: [0.065, 0.040], radius: 0.012}       # m, model plane
      - {name: table, type: plane, point: [0.0, 0.045], normal: [0.0, -1.0]}   # object on the side of −normal
      # optional on any object: its own stiffness (N/m^e) and damping (s/m) overriding model.contact,
      # break_force (N): crushed beyond it (finger_sim.grasp_objects); motion: a prescribed push or
      # vibration of the object (finger_sim.effects.contact_geometry.ObjectMotion)
    input:
      torque: {type: ramp, offset: 0.001, slope: 0.01}   # N·m, see finger_sim.inputs
      # voltage: {type: constant, value: 6.0}            # V, instead of torque when model.drive is set
      # tip_force: [{start: 0.8, end: 1.2, force: [0.0, -0.2]}]   # s, s, N: replaces model.tip_force over
      #   each span, switched at step boundaries (finger_sim.tip_force_profile; stepped by finger_node,
      #   resim and `finger-sim tasks`, refused by the paths that run one fixed system)
    initial: {theta1: 0.0, theta1_dot: 0.0}             # rad, rad/s
    duration: 0.3                # s
    integrator: {method: auto, dt: 0.001}               # method: a name in METHODS, or auto
    sensors: {seed: 0, motor_current: {noise: 0.002}}   # measured columns beside the truth, see finger_sim.sensors

Files are YAML 1.2 (`1e-3` is a number) read by `finger_sim.scene_yaml`: no duplicate keys,
anchors, aliases or tags. Values are bounded to what a finger can be (the MAX_* constants),
which also keeps every product finite; a run is at most MAX_STEPS steps.

Only the effects a scene turns on become force elements, so an absent effect costs
nothing per step.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from finger_sim import kinematics
from finger_sim.actuators.drive import Drive, DriveParams, DrivenSystem, drive_from_dict
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError
from finger_sim.effects import ForceElement, build_elements, declared_parameters
from finger_sim.effects.friction_modes import (FRICTION_KEYS, STICK_SLIP, FrictionLaw, friction_law_from_dict,
                                               split_friction_keys)
from finger_sim.effects.contact_geometry import (
    PHALANX_RADII,
    Circle,
    ContactParams,
    SceneObject,
    Vec2,
    contact_params_from_dict,
    objects_from_list,
    phalanx_radii_from_value,
)
from finger_sim.inputs import BREAK_EPS, Constant, Profile, Ramp, profile_from_dict
from finger_sim.tip_force_profile import TipForceSpan, spans_from_list
from finger_sim.integrators import METHODS
from finger_sim.model import FingerParams
from finger_sim.sensors import SensorSet, sensors_from_dict
from finger_sim.scene_yaml import dump_scene, magnitude, mapping, number, pair, parse_scene_text, read_scene_file, text

AUTO = "auto"
#: `integrator.tolerance`: the global error on θ (rad) that `method: auto` delivers; its range
#: (below 1e-10 the error-controlled path meets round-off and the bench's reference floor).
DEFAULT_TOLERANCE, MIN_TOLERANCE, MAX_TOLERANCE = 1e-6, 1e-10, 1e-2
#: A scene name is one safe file-name component (it names log files): these characters,
#: not starting with a dot, at most NAME_LENGTH of them.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
NAME_LENGTH = 64
#: Longest description, characters (it is stored in every log's metadata).
DESCRIPTION_LENGTH = 4096
#: Bounds of the model's values: far beyond any finger. The effects declare their own
#: (`finger_sim.effects.parameters`, read by `_effect_value`).
MAX_RATE = 1e4  # rad/s, the initial θ1'
MAX_DT = 1.0  # s
#: Most steps a scene may ask for: 1e12 steps of float64 states are ~100 TB, and
#: step·dt stops being exact well before 2⁵³.
MAX_STEPS = 10**12
#: Bounds of the contact law (spec §7; its default k_c is 1e5, the near-rigid scene's 1e7): they
#: keep the stability check's contact mode finite (k_c e δ^(e−1), μ F / v_s).
MAX_CONTACT_STIFFNESS = 1e12  # N/m^e
MAX_CONTACT_EXPONENT = 4.0  # Hertz is 1.5
MAX_CONTACT_DAMPING = 1e3  # s/m
MAX_FRICTION = 10.0
MIN_SLIP_VELOCITY = 1e-9  # m/s
#: Largest object coordinate or radius, and phalanx radius, m (a finger is ~0.1 m).
MAX_EXTENT = 10.0
_TOP_KEYS = {"name", "description", "model", "input", "initial", "duration", "integrator", "objects", "sensors"}
_MODEL_KEYS = {
    "spring_stiffness", "damping", "gravity", "tip_force", "joint_limits", "restitution", "geometry", "phalanx_radius", "contact",
    "drive",
}


@dataclass(frozen=True)
class Scene:
    """A fully resolved scene: every default filled in, SI units."""

    name: str = "scene"
    description: str = ""
    params: FingerParams = field(default_factory=FingerParams)
    spring_stiffness: float = declared_parameters()["spring_stiffness"].default  # the effects' declared defaults
    damping: float = declared_parameters()["damping"].default
    gravity: tuple[float, float] = declared_parameters()["gravity"].default
    tip_force: tuple[float, float] = declared_parameters()["tip_force"].default
    mcp_limits: tuple[float, float] | None = None
    restitution: float = declared_parameters()["restitution"].default
    phalanx_radius: Vec2 = PHALANX_RADII
    contact: ContactParams = field(default_factory=ContactParams)
    #: the contacts' friction law (spec §7): regularized (default) or stick_slip
    friction_law: FrictionLaw = field(default_factory=FrictionLaw)
    objects: tuple[SceneObject, ...] = ()
    #: the drive (spec §8), or None: an ideal torque source
    drive: DriveParams | None = None
    #: the scene's input profile: the motor torque τ (N·m), or with a drive the voltage command u (V)
    torque: Profile = field(default_factory=lambda: Ramp(offset=0.001, slope=0.01))
    theta1: float = 0.0
    theta1_dot: float = 0.0
    duration: float = 0.3
    method: str = AUTO
    dt: float = 0.001
    #: the global accuracy `method: auto` promises on θ, rad (finger_sim.auto)
    tolerance: float = DEFAULT_TOLERANCE
    #: measurement models read from the outputs after the step (finger_sim.sensors), or None
    sensors: SensorSet | None = None
    #: the tip-force profile (`input.tip_force`): spans over which a force replaces `tip_force`
    tip_force_profile: tuple[TipForceSpan, ...] = ()
    #: (key, value) of every declared effect parameter that is no field above, in registration order:
    #: a new effect's keys, read, dumped and validated through its declarations alone (`effect_value`)
    effect_values: tuple[tuple[str, Any], ...] = ()

    def effect_value(self, key: str) -> Any:
        """The value of the declared effect parameter `model.<key>` (SI, its declaration's default when absent)."""
        return getattr(self, key) if key in _FIELD_KEYS else dict(self.effect_values)[key]

    @property
    def step_count(self) -> int:
        """Steps of dt that cover the duration: ceil(duration/dt), a step ending within
        BREAK_EPS·dt of the duration counting as ending on it."""
        return math.ceil(self.duration / self.dt - BREAK_EPS)

    def force_elements(self) -> list[ForceElement]:
        """The elements of the effects the scene turns on (finger_sim.effects), in summation order."""
        return build_elements(self)

    def build_system(self) -> FingerSystem:
        if self.drive is not None:
            return DrivenSystem(self.params, build_elements(self), Drive(self.drive))
        return FingerSystem(self.params, build_elements(self))

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
            "phalanx_radius": list(self.phalanx_radius),
            "contact": asdict(self.contact) | self.friction_law.to_dict(),
        }
        if self.mcp_limits is not None:
            model["joint_limits"] = {"mcp": list(self.mcp_limits)}
        if self.drive is not None:
            model["drive"] = self.drive.to_dict()
        model.update((k, list(v) if isinstance(v, tuple) else v) for k, v in self.effect_values)
        return {
            "name": self.name,
            "description": self.description,
            "model": model,
            "input": {"torque" if self.drive is None else "voltage": self.torque.to_dict()}
            | ({"tip_force": [s.to_dict() for s in self.tip_force_profile]} if self.tip_force_profile else {}),
            "initial": {"theta1": self.theta1, "theta1_dot": self.theta1_dot},
            "duration": self.duration,
            "integrator": {"method": self.method, "dt": self.dt, "tolerance": self.tolerance},
            "objects": [_object_dict(obj) for obj in self.objects],
        } | ({} if self.sensors is None else {"sensors": self.sensors.to_dict()})

    def to_yaml(self) -> str:
        """The resolved scene as YAML 1.2 that `load_scene` and `scene_from_yaml` read back."""
        return dump_scene(self.to_dict())

    def with_overrides(self, *, method: str | None = None, dt: float | None = None, duration: float | None = None,
                       tolerance: float | None = None) -> Scene:
        """A copy with command-line overrides, validated like the file's values."""
        data = self.to_dict()
        if tolerance is not None:
            data["integrator"]["tolerance"] = tolerance
        if method is not None:
            data["integrator"]["method"] = method
        if dt is not None:
            data["integrator"]["dt"] = dt
        if duration is not None:
            data["duration"] = duration
        return scene_from_dict(data)


#: The Scene fields that hold a declared effect parameter themselves (the original effects').
_FIELD_KEYS = frozenset(f.name for f in fields(Scene))


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; ConfigError names the file, key, allowed values and value."""
    path = Path(path)
    data = read_scene_file(path)
    if data is not None and not isinstance(data, dict):  # e.g. /etc/passwd: name the file, show none of it
        raise ConfigError("scene", "a YAML mapping of scene keys", f"{path}: a {type(data).__name__}, not a mapping")
    try:
        return scene_from_dict({} if data is None else data, default_name=safe_name(path.stem))
    except ConfigError as exc:
        raise exc.within(path.name) from None


def scene_from_yaml(text: str, source: str = "scene") -> Scene:
    """A scene from YAML text (e.g. a log's metadata record), read like a scene file."""
    data = parse_scene_text(text, source)
    return scene_from_dict({} if data is None else data)


def safe_name(stem: str) -> str:
    """A valid scene name made from a file stem: other characters become '_', a leading dot too."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)[:NAME_LENGTH]
    name = "_" + name[1:] if name.startswith(".") else name
    return name or Scene.name


def scene_from_dict(data: Any, *, default_name: str = "scene") -> Scene:
    """Validate a scene mapping (as loaded from YAML) into a Scene."""
    data = mapping(data, "scene", _TOP_KEYS)
    model = mapping(data.get("model", {}), "model", _MODEL_KEYS | set(declared_parameters()))
    geometry = mapping(model.get("geometry", {}), "model.geometry", {f.name for f in fields(FingerParams)})
    params = FingerParams(**{k: number(v, f"model.geometry.{k}") for k, v in geometry.items()})
    inp = mapping(data.get("input", {}), "input", {"torque", "voltage", "tip_force"})
    drive = drive_from_dict(model["drive"]) if "drive" in model else None
    input_key = _input_key(inp, drive)
    initial = mapping(data.get("initial", {}), "initial", {"theta1", "theta1_dot"})
    integ = mapping(data.get("integrator", {}), "integrator", {"method", "dt", "tolerance"})
    method = integ.get("method", Scene.method)
    if not isinstance(method, str) or (method not in METHODS and method != AUTO):
        raise ConfigError("integrator.method", f"one of {sorted(METHODS) + [AUTO]}", method)
    name = text(data.get("name", default_name), "name", NAME_LENGTH)
    if not NAME_PATTERN.fullmatch(name):
        raise ConfigError("name", "a file-name component of letters, digits, '_', '.' and '-', not starting with '.'", name)
    limits = mapping(model.get("joint_limits", {}), "model.joint_limits", {"mcp"})
    mcp = None
    if "mcp" in limits:
        mcp = pair(limits["mcp"], "model.joint_limits.mcp")
        if not mcp[0] < mcp[1]:
            raise ConfigError("model.joint_limits.mcp", "[lower, upper] with lower < upper (rad)", list(mcp))
        lo, hi = kinematics.assembly_range(params)
        if not (lo < mcp[0] and mcp[1] < hi):
            raise ConfigError("model.joint_limits.mcp", f"limits inside the assemblable range ({lo:.6f}, {hi:.6f}) rad", list(mcp))
    duration = number(data.get("duration", Scene.duration), "duration", minimum=0.0, strict=True)
    dt = number(integ.get("dt", Scene.dt), "integrator.dt", minimum=0.0, maximum=MAX_DT, strict=True)
    _check_steps(duration, dt)
    scene = Scene(
        name=name,
        description=text(data.get("description", ""), "description", DESCRIPTION_LENGTH),
        params=params,
        spring_stiffness=_effect_value(model, "spring_stiffness"),
        damping=_effect_value(model, "damping"),
        gravity=_effect_value(model, "gravity"),
        tip_force=_effect_value(model, "tip_force"),
        mcp_limits=mcp,
        restitution=_effect_value(model, "restitution"),
        phalanx_radius=_phalanx_radius(model.get("phalanx_radius")),
        contact=_contact(model.get("contact")),
        friction_law=_friction_law(model, data.get("objects")),
        objects=_objects(data.get("objects")),
        drive=drive,
        torque=(profile_from_dict(inp[input_key], f"input.{input_key}") if input_key in inp
                else Ramp(offset=0.001, slope=0.01) if drive is None else Constant(value=drive.supply_voltage)),
        theta1=number(initial.get("theta1", Scene.theta1), "initial.theta1"),
        theta1_dot=magnitude(initial.get("theta1_dot", Scene.theta1_dot), "initial.theta1_dot", MAX_RATE),
        duration=duration,
        method=method,
        dt=dt,
        tolerance=number(integ.get("tolerance", Scene.tolerance), "integrator.tolerance", minimum=MIN_TOLERANCE,
                         maximum=MAX_TOLERANCE),
        sensors=(sensors_from_dict(data["sensors"], has_drive=drive is not None, has_objects=bool(data.get("objects")))
                 if "sensors" in data else None),
        tip_force_profile=spans_from_list(inp["tip_force"], duration) if "tip_force" in inp else (),
        effect_values=tuple((k, _effect_value(model, k)) for k in declared_parameters() if k not in _FIELD_KEYS),
    )
    q0, _ = scene.initial_state()  # refuses a θ1 outside the assemblable range, or at a toggle
    for element in build_elements(scene):  # through the registry: an element that must start clear checks it
        check_clearance = getattr(element, "check_clearance", None)
        if check_clearance is not None:
            check_clearance(q0)  # contact: an object overlapping a phalanx at the start names objects[i]
    if mcp is not None and not (mcp[0] <= scene.theta1 <= mcp[1]):
        raise ConfigError("initial.theta1", f"an angle within model.joint_limits.mcp {list(mcp)} rad", scene.theta1)
    if scene.dt > scene.duration:
        raise ConfigError("integrator.dt", f"a step no longer than duration ({scene.duration} s)", scene.dt)
    if scene.dt > scene.torque.shortest_interval():
        raise ConfigError(
            f"input.{input_key}.frequency",
            f"at most {0.5 / scene.dt:g} Hz at integrator.dt = {scene.dt:g} s (a step of at most half a period: "
            f"a faster {scene.torque.kind} wave changes direction more than once per step, which the step cannot resolve)",
            scene.torque.to_dict()["frequency"],  # only periodic profiles have a shortest interval
        )
    return scene


def _input_key(inp: dict[str, Any], drive: DriveParams | None) -> str:
    """The input's key: `torque` without a drive, `voltage` with one; the other one is refused."""
    if drive is not None and "torque" in inp:
        raise ConfigError("input.torque", "no torque with model.drive (the drive's input is input.voltage, V)",
                          inp["torque"])
    if drive is None and "voltage" in inp:
        raise ConfigError("input.voltage", "a voltage only with model.drive (without it the input is input.torque, N·m)",
                          inp["voltage"])
    return "torque" if drive is None else "voltage"


def _phalanx_radius(value: Any) -> Vec2:
    """`model.phalanx_radius`, each radius at most MAX_EXTENT."""
    radii = phalanx_radii_from_value(value)
    for i, r in enumerate(radii):
        number(r, f"model.phalanx_radius[{i}]", maximum=MAX_EXTENT)
    return radii


def _effect_value(model: dict[str, Any], key: str) -> Any:
    """`model.<key>` read through the declaration of the effect that owns it (its default when absent)."""
    parameter = declared_parameters()[key]
    return parameter.read(model.get(key, parameter.default), f"model.{key}")


def _contact(value: Any) -> ContactParams:
    """`model.contact` (spec §7 defaults), bounded by the MAX_CONTACT_* constants."""
    params = contact_params_from_dict(split_friction_keys(value)[0], also=FRICTION_KEYS)
    key = "model.contact."
    number(params.stiffness, key + "stiffness", maximum=MAX_CONTACT_STIFFNESS)
    number(params.exponent, key + "exponent", maximum=MAX_CONTACT_EXPONENT)
    number(params.damping, key + "damping", maximum=MAX_CONTACT_DAMPING)
    number(params.friction, key + "friction", maximum=MAX_FRICTION)
    number(params.slip_velocity, key + "slip_velocity", minimum=MIN_SLIP_VELOCITY)
    return params


def _friction_law(model: dict[str, Any], objects: Any) -> FrictionLaw:
    """The friction law's keys of `model.contact` (`effects.friction_modes`); stick_slip with a moving
    object is refused with a drive or joint limits, which `stick_slip_moving` does not cover yet."""
    value = model.get("contact")
    law = friction_law_from_dict(split_friction_keys(value)[1], _contact(value).friction)
    if law.model == STICK_SLIP:
        moving = isinstance(objects, list) and any(isinstance(o, dict) and "motion" in o for o in objects)
        if moving and (model.get("drive") is not None or model.get("joint_limits") is not None):
            raise ConfigError("model.contact.friction_model", "regularized with a moving object and a drive or "
                              f"joint_limits ({STICK_SLIP} with a moving object covers neither yet)", STICK_SLIP)
    return law


def _objects(value: Any) -> tuple[SceneObject, ...]:
    """Top-level `objects` (omitted or [] = none): names at most NAME_LENGTH characters,
    coordinates and radii within MAX_EXTENT."""
    objects = objects_from_list(value)
    for i, obj in enumerate(objects):
        where = f"objects[{i}]"
        text(obj.name, f"{where}.name", NAME_LENGTH)
        if isinstance(obj, Circle):
            pair(obj.center, f"{where}.center", MAX_EXTENT)
            number(obj.radius, f"{where}.radius", maximum=MAX_EXTENT)
        else:
            pair(obj.point, f"{where}.point", MAX_EXTENT)
        if obj.properties.stiffness is not None:
            number(obj.properties.stiffness, f"{where}.stiffness", maximum=MAX_CONTACT_STIFFNESS)
        if obj.properties.damping is not None:
            number(obj.properties.damping, f"{where}.damping", maximum=MAX_CONTACT_DAMPING)
    return objects


def _object_dict(obj: SceneObject) -> dict[str, Any]:
    """One object in the `objects:` schema."""
    if isinstance(obj, Circle):
        return {"name": obj.name, "type": "circle", "center": list(obj.center), "radius": obj.radius, **obj.properties.to_dict()}
    return {"name": obj.name, "type": "plane", "point": list(obj.point), "normal": list(obj.normal), **obj.properties.to_dict()}


def _check_steps(duration: float, dt: float) -> None:
    """Refuse a run of more than MAX_STEPS steps, stating the count."""
    steps = duration / dt  # a float: may be far beyond any int a run could reach, or inf
    if steps > MAX_STEPS:
        raise ConfigError(
            "duration",
            f"a run of at most {MAX_STEPS:.0e} steps (duration ≤ {MAX_STEPS * dt:.3g} s at integrator.dt = {dt:g} s)",
            f"{duration:g} s = {steps:.3g} steps",
        )
