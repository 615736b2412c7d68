"""Scenes: every shipped file read back with an independent YAML read, round trips, and
every refusal with its exact message (key, what is allowed, what arrived)."""

from __future__ import annotations

import math
import os
import re
from dataclasses import asdict

import pytest
import yaml

import reference as ref
from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_geometry import Circle, ContactParams, Plane
from finger_sim.errors import ConfigError, shown
from finger_sim.inputs import Constant, Ramp, Sine, Square, Step
from finger_sim.integrators import METHODS
from finger_sim.kinematics import assembly_range
from finger_sim.model import FingerParams
from finger_sim.scene import Scene, load_scene, scene_from_dict

#: Every scene in config/ (finger_node.yaml there is the node's ROS parameter file).
SHIPPED = sorted(p for p in ref.CONFIG.glob("*.yaml") if p.name != "finger_node.yaml")
LO, HI = assembly_range(FingerParams())


def test_every_scene_is_shipped():
    assert [p.stem for p in SHIPPED] == [
        "bang_bang", "drive_grasp", "drive_grasp_backdrivable", "finger_default", "free_swing", "grasp_cylinder", "grasp_impact", "grasp_rigid",
        "paper_flexion", "paper_to_stop", "press_table", "stiff_spring", "toggle_passage",
    ]


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_scene_holds_the_numbers_in_its_file(path):
    raw = yaml.safe_load(path.read_text())
    scene = load_scene(path)
    model = raw.get("model", {})
    assert scene.name == path.stem
    assert scene.description == raw["description"]
    assert scene.spring_stiffness == model.get("spring_stiffness", 0.001)
    assert scene.damping == model.get("damping", 0.0)
    assert scene.restitution == model.get("restitution", 0.0)
    limits = model.get("joint_limits", {}).get("mcp")
    assert scene.mcp_limits == (tuple(limits) if limits else None)
    key = "voltage" if "drive" in model else "torque"  # the input of a scene with a drive is its voltage
    assert scene.torque.to_dict() == raw["input"][key] | ({"offset": 0.0} if raw["input"][key]["type"] == "square" else {})
    assert (scene.drive is None) == ("drive" not in model)
    assert scene.theta1 == raw.get("initial", {}).get("theta1", 0.0)
    assert scene.theta1_dot == raw.get("initial", {}).get("theta1_dot", 0.0)
    assert scene.duration == raw["duration"]
    assert (scene.method, scene.dt) == (raw["integrator"]["method"], raw["integrator"]["dt"])
    assert scene.params == FingerParams()
    assert scene.phalanx_radius == tuple(model.get("phalanx_radius", [0.008, 0.007]))
    assert asdict(scene.contact) == {**asdict(ContactParams()), **model.get("contact", {})}
    assert [_object_dict(obj) for obj in scene.objects] == raw.get("objects", [])
    # a scene with objects has the contact element, one without has none
    assert any(isinstance(e, Contact) for e in scene.force_elements()) == bool(raw.get("objects"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_round_trip_through_dict_and_yaml(path, tmp_path):
    scene = load_scene(path)
    assert scene_from_dict(scene.to_dict(), default_name="other") == scene
    copy = tmp_path / "copy.yaml"
    copy.write_text(scene.to_yaml())
    assert load_scene(copy) == scene
    # a different reader sees the same mapping
    assert yaml.safe_load(copy.read_text()) == scene.to_dict()


def test_round_trip_of_every_effect_and_profile():
    base = {
        "name": "all",
        "model": {
            "spring_stiffness": 0.002,
            "damping": 0.01,
            "gravity": [0.0, -9.81],
            "tip_force": [0.1, 0.2],
            "joint_limits": {"mcp": [-0.1, 1.5]},
            "restitution": 0.5,
            "geometry": {"r1": 0.047, "m3": 0.015},
        },
        "initial": {"theta1": 0.2, "theta1_dot": -1.0},
        "duration": 0.5,
        "integrator": {"method": "radau", "dt": 0.002},
    }
    profiles = [
        {"type": "constant", "value": 0.01},
        {"type": "ramp", "offset": 0.001, "slope": 0.01},
        {"type": "step", "before": 0.0, "after": 0.02, "at": 0.1},
        {"type": "square", "amplitude": 0.004, "frequency": 50.0, "offset": 0.001},
        {"type": "sine", "amplitude": 0.004, "frequency": 5.0, "offset": 0.0},
    ]
    for torque, cls in zip(profiles, (Constant, Ramp, Step, Square, Sine)):
        scene = scene_from_dict({**base, "input": {"torque": torque}})
        assert isinstance(scene.torque, cls)
        assert scene.torque.to_dict() == torque
        assert scene_from_dict(scene.to_dict()) == scene
        assert scene.params.r1 == 0.047 and scene.params.m3 == 0.015 and scene.params.r2 == 0.0444
        assert scene.mcp_limits == (-0.1, 1.5)
        assert len(scene.force_elements()) == 5  # spring, damping, gravity, tip force, MCP stops


def test_defaults_are_the_papers_run():
    scene = scene_from_dict({})
    assert scene == Scene()
    assert scene.torque == Ramp(offset=0.001, slope=0.01)
    assert (scene.spring_stiffness, scene.duration, scene.theta1, scene.dt) == (0.001, 0.3, 0.0, 0.001)
    # an absent effect is no element at all
    assert scene_from_dict({"model": {"spring_stiffness": 0}}).force_elements() == []


def test_with_overrides_validates_like_the_file():
    scene = load_scene(ref.CONFIG / "paper_flexion.yaml").with_overrides(method="radau", dt=0.002, duration=0.1)
    assert (scene.method, scene.dt, scene.duration) == ("radau", 0.002, 0.1)
    with pytest.raises(ConfigError, match=r"^integrator\.dt: expected a number > 0, got -0\.001$"):
        scene.with_overrides(dt=-0.001)


# -- refusals ----------------------------------------------------------------------------
def refusal(data) -> str:
    with pytest.raises(ConfigError) as info:
        scene_from_dict(data)
    return str(info.value)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        # unknown keys, top level and nested
        ({"modle": {}}, "scene: expected only the keys ['description', 'duration', 'initial', 'input', 'integrator', 'model', 'name', 'objects', 'sensors'], got 'modle'"),
        ({"model": {"stiffness": 1.0}}, "model: expected only the keys ['contact', 'damping', 'drive', 'geometry', 'gravity', 'joint_limits', 'phalanx_radius', 'restitution', 'spring_stiffness', 'tip_force'], got 'stiffness'"),
        ({"model": {"geometry": {"r5": 0.01}}}, "model.geometry: expected only the keys ['L3', 'm1', 'm2', 'm3', 'r1', 'r2', 'r3', 'r4', 'theta4'], got 'r5'"),
        ({"model": {"joint_limits": {"pip": [0, 1]}}}, "model.joint_limits: expected only the keys ['mcp'], got 'pip'"),
        ({"initial": {"theta2": 0.1}}, "initial: expected only the keys ['theta1', 'theta1_dot'], got 'theta2'"),
        ({"integrator": {"method": "rk4", "tol": 1e-6}}, "integrator: expected only the keys ['dt', 'method', 'tolerance'], got 'tol'"),
        ({"input": {"torque": {"type": "ramp", "offset": 0.0, "slope": 0.01, "phase": 1.0}}}, "input.torque: unknown key; expected only keys ['offset', 'slope'] (and 'type') for type ramp, got 'phase'"),
        # wrong types
        ([1, 2], "scene: expected a mapping, got [1, 2]"),
        ({"model": [1.0]}, "model: expected a mapping, got [1.0]"),
        ({"model": {"damping": "0.1"}}, "model.damping: expected a finite number (YAML 1.2 float syntax, e.g. 1.0e-3), got '0.1'"),
        ({"model": {"spring_stiffness": True}}, "model.spring_stiffness: expected a finite number, got True"),
        ({"model": {"gravity": [0.0, -9.81, 0.0]}}, "model.gravity: expected a list of two numbers, got [0.0, -9.81, 0.0]"),
        ({"model": {"tip_force": [0.0, "x"]}}, "model.tip_force[1]: expected a finite number (YAML 1.2 float syntax, e.g. 1.0e-3), got 'x'"),
        ({"model": {"geometry": {"r1": None}}}, "model.geometry.r1: expected a finite number, got None"),
        ({"duration": float("nan")}, "duration: expected a finite number, got nan"),
        ({"initial": {"theta1": "0"}}, "initial.theta1: expected a finite number (YAML 1.2 float syntax, e.g. 1.0e-3), got '0'"),
        ({"integrator": {"method": "rk5"}}, f"integrator.method: expected one of {sorted(METHODS) + ['auto']}, got 'rk5'"),
        # out of range
        ({"model": {"damping": -0.01}}, "model.damping: expected a number ≥ 0, got -0.01"),
        ({"model": {"spring_stiffness": -1.0}}, "model.spring_stiffness: expected a number ≥ 0, got -1.0"),
        ({"model": {"restitution": 1.5}}, "model.restitution: expected a number ≤ 1, got 1.5"),
        ({"model": {"restitution": -0.5}}, "model.restitution: expected a number ≥ 0, got -0.5"),
        ({"integrator": {"dt": 0}}, "integrator.dt: expected a number > 0, got 0"),
        ({"integrator": {"dt": -0.001}}, "integrator.dt: expected a number > 0, got -0.001"),
        ({"duration": 0.0}, "duration: expected a number > 0, got 0.0"),
        ({"duration": 0.01, "integrator": {"dt": 0.02}}, "integrator.dt: expected a step no longer than duration (0.01 s), got 0.02"),
        ({"model": {"geometry": {"r3": -0.0077}}}, "model.geometry.r3: expected a finite value > 0, got -0.0077"),
        # torque profiles
        ({"input": {"torque": {"type": "triangle"}}}, "input.torque.type: expected one of ['constant', 'ramp', 'sine', 'square', 'step'], got 'triangle'"),
        ({"input": {"torque": 0.01}}, "input.torque: expected a mapping with 'type' in ['constant', 'ramp', 'sine', 'square', 'step'], got 0.01"),
        ({"input": {"torque": {"type": "ramp", "offset": 0.001}}}, "input.torque.slope: expected a number (required for type ramp), got None"),
        ({"input": {"torque": {"type": "step", "before": 0.0, "after": 1.0}}}, "input.torque.at: expected a number (required for type step), got None"),
        ({"input": {"torque": {"type": "constant", "value": "high"}}}, "input.torque.value: expected a finite number (YAML 1.2 float syntax, e.g. 1.0e-3), got 'high'"),
        ({"input": {"torque": {"type": "square", "amplitude": 0.004, "frequency": 0.0}}}, "input.torque.frequency: expected a number > 0 (Hz), got 0.0"),
        ({"input": {"torque": {"type": "sine", "amplitude": 0.004, "frequency": -5.0}}}, "input.torque.frequency: expected a number > 0 (Hz), got -5.0"),
        # joint limits
        ({"model": {"joint_limits": {"mcp": [1.0, 0.5]}}}, "model.joint_limits.mcp: expected [lower, upper] with lower < upper (rad), got [1.0, 0.5]"),
        ({"model": {"joint_limits": {"mcp": [0.0]}}}, "model.joint_limits.mcp: expected a list of two numbers, got [0.0]"),
        ({"model": {"joint_limits": {"mcp": [0.0, 2.0]}}}, f"model.joint_limits.mcp: expected limits inside the assemblable range ({LO:.6f}, {HI:.6f}) rad, got [0.0, 2.0]"),
        ({"model": {"joint_limits": {"mcp": [-3.0, 1.0]}}}, f"model.joint_limits.mcp: expected limits inside the assemblable range ({LO:.6f}, {HI:.6f}) rad, got [-3.0, 1.0]"),
        ({"model": {"joint_limits": {"mcp": [0.0, 1.0]}}, "initial": {"theta1": 1.2}}, "initial.theta1: expected an angle within model.joint_limits.mcp [0.0, 1.0] rad, got 1.2"),
        # initial θ1 outside the assemblable range (spec §1: −160.36° .. 104.21°)
        ({"initial": {"theta1": 1.9}}, f"initial.theta1: expected an MCP angle in the assemblable range [{LO:.6f}, {HI:.6f}] rad, got 1.9"),
        ({"initial": {"theta1": -2.9}}, f"initial.theta1: expected an MCP angle in the assemblable range [{LO:.6f}, {HI:.6f}] rad, got -2.9"),
    ],
)
def test_refusal_names_key_allowed_and_value(data, message):
    assert refusal(data) == message


def test_range_in_the_message_is_the_spec_toggles():
    assert math.degrees(LO) == pytest.approx(-160.3615, abs=5e-5)
    assert math.degrees(HI) == pytest.approx(104.2116, abs=5e-5)
    assert refusal({"initial": {"theta1": HI + 1e-6}}).startswith("initial.theta1: expected an MCP angle in the assemblable range")
    # just inside assembles
    assert scene_from_dict({"initial": {"theta1": HI - 1e-6}}).theta1 == HI - 1e-6
    # exactly at a toggle the θ1-parametrized start is singular (dθ3/dθ1 unbounded): refused
    for toggle in (HI, LO):
        assert refusal({"initial": {"theta1": toggle}}) == f"initial.theta1: expected a pose away from the toggle (θ2 ∥ θ3), got {toggle!r}"


def test_load_scene_prefixes_the_file_name(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("model: {damping: -1}\n")
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert str(info.value) == "bad.yaml: model.damping: expected a number ≥ 0, got -1"
    assert info.value.key == "bad.yaml: model.damping"


def test_load_scene_refuses_an_unreadable_file(tmp_path):
    missing = tmp_path / "missing.yaml"
    with pytest.raises(ConfigError) as info:
        load_scene(missing)
    assert str(info.value) == f"scene: expected a readable scene file, got '{missing} (No such file or directory)'"
    with pytest.raises(ConfigError, match=r"^scene: expected a readable scene file, got '.*Is a directory\)'$"):
        load_scene(tmp_path)
    if os.geteuid() != 0:  # root reads anything
        locked = tmp_path / "locked.yaml"
        locked.write_text("{}")
        locked.chmod(0)
        with pytest.raises(ConfigError, match="Permission denied"):
            load_scene(locked)


@pytest.mark.parametrize("text", ["model: [1, 2\n", "model:\n  damping: 1\n bad indent: 2\n", "a: b: c\n"])
def test_load_scene_refuses_invalid_yaml(tmp_path, text):
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    msg = str(info.value)
    assert re.match(rf"^scene: expected valid YAML, got [\"']{re.escape(str(path))}: line \d+, column \d+: ", msg)
    assert "\n" not in msg


def test_empty_file_is_the_default_scene(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    assert load_scene(path) == Scene(name="empty")


def test_a_yaml_that_is_not_a_mapping_is_refused(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match=r"^scene: expected a YAML mapping of scene keys, got '.*list\.yaml: a list, not a mapping'$"):
        load_scene(path)


def test_refusals_are_value_errors_too():
    """ConfigError subclasses ValueError, so generic callers can catch it."""
    with pytest.raises(ValueError):
        scene_from_dict({"duration": -1})


# -- issue 8: names, bounds, resources, defaults -------------------------------------------
@pytest.mark.parametrize("name", ["../X", "/tmp/X", ".hidden", "a/b", "", "x" * 65, "tab\there", "..", "naïve"])
def test_a_name_must_be_a_safe_file_name_component(name):
    """The name becomes the log's file name: `../X` and `/tmp/X` wrote outside record_dir."""
    msg = refusal({"name": name})
    if len(name) > 64:
        assert msg == "name: expected a string of at most 64 characters, got '65 characters'"
    else:
        assert msg == f"name: expected a file-name component of letters, digits, '_', '.' and '-', not starting with '.', got {name!r}"


def test_names_that_are_not_strings_are_refused():
    assert refusal({"name": ["x"]}) == "name: expected a string, got ['x']"
    assert refusal({"description": {"a": 1}}) == "description: expected a string, got {'a': 1}"
    assert scene_from_dict({"name": "finger-2_v1.0"}).name == "finger-2_v1.0"


def test_default_name_from_a_file_stem_is_made_safe(tmp_path):
    for stem, name in [("my scene (copy)", "my_scene__copy_"), (".hidden", "_hidden"), ("ok-1.2", "ok-1.2")]:
        path = tmp_path / f"{stem}.yaml"
        path.write_text("duration: 0.1\n")
        assert load_scene(path).name == name


def test_an_unhashable_method_names_the_key():
    """`integrator: {method: [rk4]}` raised TypeError: unhashable type: 'list'."""
    assert refusal({"integrator": {"method": ["rk4"]}}) == f"integrator.method: expected one of {sorted(METHODS) + ['auto']}, got ['rk4']"
    assert refusal({"input": {"torque": {"type": ["ramp"]}}}).startswith("input.torque.type: expected one of")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        # damping 1e300 used to end in the stability check's "… or dt ≤ nan s"
        ({"model": {"damping": 1e300}}, "model.damping: expected a number ≤ 1000, got 1e+300"),
        ({"model": {"spring_stiffness": 1e7}}, "model.spring_stiffness: expected a number ≤ 1e+06, got 10000000.0"),
        ({"model": {"gravity": [0.0, -1e300]}}, "model.gravity[1]: expected a number with magnitude ≤ 10000, got -1e+300"),
        ({"model": {"tip_force": [1e5, 0.0]}}, "model.tip_force[0]: expected a number with magnitude ≤ 10000, got 100000.0"),
        ({"initial": {"theta1_dot": 1e300}}, "initial.theta1_dot: expected a number with magnitude ≤ 10000, got 1e+300"),
        ({"input": {"torque": {"type": "constant", "value": 1e300}}}, "input.torque.value: expected a number with magnitude ≤ 1000, got 1e+300"),
        ({"input": {"torque": {"type": "ramp", "offset": 0.0, "slope": -1e9}}}, "input.torque.slope: expected a number with magnitude ≤ 1e+06, got -1000000000.0"),
        ({"duration": 10**400}, f"duration: expected a finite number, got {shown(10**400)}"),  # cut: bounded
        ({"integrator": {"dt": 2.0}, "duration": 10.0}, "integrator.dt: expected a number ≤ 1, got 2.0"),
    ],
)
def test_physically_absurd_values_are_refused_with_their_bound(data, message):
    assert refusal(data) == message


def test_a_run_beyond_the_step_ceiling_is_refused_with_its_step_count():
    """`duration: 1e38` ran until the machine ran out of memory."""
    assert refusal({"duration": 1e38}) == (
        "duration: expected a run of at most 1e+12 steps (duration ≤ 1e+09 s at integrator.dt = 0.001 s), got '1e+38 s = 1e+41 steps'"
    )
    assert refusal({"integrator": {"dt": 1e-320}}).endswith("got '0.3 s = inf steps'")  # no OverflowError in ceil(inf)


def test_a_square_wave_faster_than_the_step_is_refused():
    """A 1e9 Hz square wave put 2e6 switches into each 1 ms step."""
    square = {"type": "square", "amplitude": 0.004, "frequency": 1e9}
    assert refusal({"input": {"torque": square}}) == (
        "input.torque.frequency: expected at most 500 Hz at integrator.dt = 0.001 s (a step of at most half a period: "
        "a faster square wave changes direction more than once per step, which the step cannot resolve), got 1000000000.0"
    )
    # the limit is one switch per step; it moves with dt (e.g. the node's physics_rate_hz)
    scene = scene_from_dict({"input": {"torque": {**square, "frequency": 500.0}}})  # at the limit
    slower = scene_from_dict({"input": {"torque": {**square, "frequency": 400.0}}})
    assert max(len(slower.torque.breakpoints(k * 0.001, (k + 1) * 0.001)) for k in range(300)) == 1
    with pytest.raises(ConfigError, match=r"^input\.torque\.frequency: expected at most 250 Hz at integrator\.dt = 0\.002 s"):
        scene.with_overrides(dt=0.002)
    sine = {"type": "sine", "amplitude": 0.004, "frequency": 600.0}
    assert refusal({"input": {"torque": sine}}).startswith("input.torque.frequency: expected at most 500 Hz")


@pytest.mark.parametrize(("duration", "dt", "steps"), [(0.3, 0.001, 300), (0.3, 0.0007, 429), (1.0, 0.1, 10), (2.0, 0.001, 2000), (0.1, 0.03, 4)])
def test_step_count_covers_the_duration(duration, dt, steps):
    scene = scene_from_dict({"duration": duration, "integrator": {"dt": dt}})
    assert scene.step_count == steps
    # the smallest whole number of steps reaching the duration, up to BREAK_EPS of a step
    assert (steps - 1) * dt < duration * (1 - 1e-12) and steps * dt >= duration * (1 - 1e-12)


def test_the_default_method_is_auto():
    """Issue 8.7: a scene that named no method stepped with rk4."""
    assert Scene().method == "auto" and scene_from_dict({}).method == "auto"
    assert scene_from_dict({"integrator": {"dt": 0.002}}).to_dict()["integrator"]["method"] == "auto"


# -- issue 12: objects, contact law, phalanx radii ---------------------------------------------
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.04], "radius": 0.012}
TABLE = {"name": "table", "type": "plane", "point": [0.0, 0.045], "normal": [0.0, -1.0]}


def _object_dict(obj) -> dict:
    """An object back in the schema, written here independently of Scene.to_dict."""
    if isinstance(obj, Circle):
        return {"name": obj.name, "type": "circle", "center": list(obj.center), "radius": obj.radius}
    return {"name": obj.name, "type": "plane", "point": list(obj.point), "normal": list(obj.normal)}


def test_objects_contact_and_radii_are_read_and_round_trip(tmp_path):
    data = {
        "model": {"phalanx_radius": [0.009, 0.006], "contact": {"stiffness": 2.0e5, "exponent": 1.0, "damping": 0.5, "friction": 0.3, "slip_velocity": 0.01}},
        "objects": [CUP, {**TABLE, "normal": [0.3, -2.0]}],
    }
    scene = scene_from_dict(data)
    assert scene.phalanx_radius == (0.009, 0.006)
    assert scene.contact == ContactParams(2.0e5, 1.0, 0.5, 0.3, 0.01)
    assert scene.objects[0] == Circle("cup", (0.065, 0.04), 0.012)
    plane = scene.objects[1]
    assert isinstance(plane, Plane) and math.hypot(*plane.normal) == pytest.approx(1.0, abs=1e-15)
    assert plane.normal[0] / plane.normal[1] == pytest.approx(0.3 / -2.0, rel=1e-15)
    (contact,) = [e for e in scene.force_elements() if isinstance(e, Contact)]
    assert (contact.radii, contact.contact, contact.objects) == (scene.phalanx_radius, scene.contact, scene.objects)
    # the log stores the resolved scene: it reads back equal (the normalized normal bit for bit)
    assert scene_from_dict(scene.to_dict()) == scene
    copy = tmp_path / "copy.yaml"
    copy.write_text(scene.to_yaml())
    assert load_scene(copy) == scene
    assert yaml.safe_load(copy.read_text())["objects"][1]["normal"] == list(plane.normal)


def test_no_objects_means_no_contact_element_and_the_spec_defaults():
    for data in ({}, {"objects": []}, {"objects": None}):
        scene = scene_from_dict(data)
        assert scene.objects == () and not any(isinstance(e, Contact) for e in scene.force_elements())
    scene = scene_from_dict({"objects": [CUP]})
    assert scene.phalanx_radius == (0.008, 0.007)
    assert scene.contact == ContactParams(stiffness=1.0e5, exponent=1.5, damping=1.5, friction=0.0, slip_velocity=1.0e-3)
    assert scene.to_dict()["model"]["contact"] == {"stiffness": 1.0e5, "exponent": 1.5, "damping": 1.5, "friction": 0.0, "slip_velocity": 1.0e-3}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"objects": [{**CUP, "radius": 0.0}]}, "objects[0].radius: expected a finite radius > 0 (m), got 0.0"),
        ({"objects": [CUP, {**TABLE, "normal": [0.0, 0.0]}]}, "objects[1].normal: expected a non-zero direction (|n| ≥ 1e-09; it is normalized), got [0.0, 0.0]"),
        ({"objects": [{**CUP, "type": "box"}]}, "objects[0].type: expected one of ['circle', 'plane'], got 'box'"),
        ({"objects": [{"name": "t", "type": "plane", "point": [0.0, 0.05]}]}, "objects[0].normal: expected a value (required for a plane), got None"),
        ({"objects": {"cup": CUP}}, "objects: expected a list of objects ({name, type: circle|plane, ...}), got {'cup': " + repr(CUP) + "}"),
        ({"objects": [CUP, {**CUP, "center": [0.0, 0.09]}]}, "objects[1].name: expected a name no other object uses, got 'cup'"),
        ({"objects": [{**CUP, "center": [0.065, 1e300]}]}, "objects[0].center[1]: expected a number with magnitude ≤ 10, got 1e+300"),
        ({"objects": [{**CUP, "radius": 100.0}]}, "objects[0].radius: expected a number ≤ 10, got 100.0"),
        ({"objects": [{**CUP, "name": "x" * 65}]}, "objects[0].name: expected a string of at most 64 characters, got '65 characters'"),
        ({"model": {"contact": {"stiffness": -1.0}}}, "model.contact.stiffness: expected a finite number > 0, got -1.0"),
        ({"model": {"contact": {"stiffness": 1e300}}}, "model.contact.stiffness: expected a number ≤ 1e+12, got 1e+300"),
        ({"model": {"contact": {"exponent": 1e300}}}, "model.contact.exponent: expected a number ≤ 4, got 1e+300"),
        ({"model": {"contact": {"slip_velocity": 1e-300}}}, "model.contact.slip_velocity: expected a number ≥ 1e-09, got 1e-300"),
        ({"model": {"contact": {"stifness": 1.0}}}, "model.contact: expected only the keys ['damping', 'exponent', 'friction', 'friction_model', 'slip_velocity', 'static_friction', 'stiffness', 'stribeck_velocity'], got 'stifness'"),
        ({"model": {"phalanx_radius": [0.008]}}, "model.phalanx_radius: expected [proximal, distal] capsule radii (m), got [0.008]"),
        ({"model": {"phalanx_radius": [0.008, -0.007]}}, "model.phalanx_radius[1]: expected a finite radius > 0 (m), got -0.007"),
    ],
)
def test_bad_objects_and_contact_values_are_refused_naming_the_key(data, message):
    assert refusal(data) == message


def test_an_object_overlapping_a_phalanx_at_the_initial_state_is_refused(tmp_path):
    """The distal capsule's axis ends at the tip (0.0885, 0) at θ1 = 0: a cup 1 mm into it is refused."""
    tip_x = FingerParams().r1 + FingerParams().L3
    mug = {"name": "mug", "type": "circle", "center": [tip_x + 0.007 + 0.012 - 0.001, 0.0], "radius": 0.012}
    msg = refusal({"objects": [CUP, mug]})
    assert msg.startswith("objects[1]: expected an object clear of the phalanges at the initial state (overlap ≤ 0.0001 m), got ")
    assert "'mug' overlaps the distal phalanx by 0.001" in msg and "\n" not in msg
    # the same cup is clear at another initial pose, and within the tolerance it is accepted
    assert scene_from_dict({"objects": [mug], "initial": {"theta1": 0.3}}).objects[0].name == "mug"
    mug["center"][0] += 0.001 - 0.5e-4
    assert scene_from_dict({"objects": [mug]}).objects[0].name == "mug"
    # through a file, the refusal names the file too
    path = tmp_path / "overlap.yaml"
    path.write_text(yaml.safe_dump({"objects": [{**mug, "center": [tip_x + 0.018, 0.0]}]}))
    with pytest.raises(ConfigError, match=r"^overlap\.yaml: objects\[0\]: expected an object clear of the phalanges"):
        load_scene(path)
