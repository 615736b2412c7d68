"""The finger's URDF, read by an independent library (yourdfpy) and checked against the model.

References: spec §1's geometry written out again here for any parameters (`model_points`),
checked against `reference.py`'s independent Newton assembly for the paper's finger; spec §2's
masses and rod inertias; the node's joint-state formulas (`finger_sim.joints`, what
`ros/conversions.joint_state` publishes). yourdfpy's forward kinematics at those joint
positions must put `fingertip` on the model's tip and close the loop at C, to 1e-12 m.
"""

from __future__ import annotations

import io
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

import reference as ref
from finger_sim import joints, kinematics
from finger_sim.cli import main as cli
from finger_sim.errors import ConfigError
from finger_sim.model import FingerParams
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate
from finger_sim.urdf import MCP_EFFORT_LIMIT, PHALANX_RADII, finger_urdf, hand_urdf

yourdfpy = pytest.importorskip("yourdfpy")

ROOT = Path(__file__).resolve().parents[2]
INSTALLED = ROOT / "urdf" / "finger.urdf"
ROS2_CONTROL = ROOT / "config" / "ros2_control"
P = FingerParams()
#: Forward kinematics against the model, m (and rotation-matrix entries): round-off.
TOL = 1e-12
LINKS = ("finger_base", "proximal_link", "coupler_link", "distal_link", "fingertip")


def load(text: str) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(io.StringIO(text), load_meshes=False)


def model_points(p: FingerParams, q) -> dict[str, np.ndarray]:
    """Spec §1 for any parameters: B, C (coupler side), C (distal side), tip in the model plane, and ψ."""
    e = lambda a: np.array([math.cos(a), math.sin(a)])  # noqa: E731
    d = -p.r4 * e(p.theta4)
    b = p.r1 * e(q[0])
    # α makes the finger straight at extension: θ3_ext on the spec's branch is θ3 at θ1 = 0.
    alpha = -kinematics.extended_pose(p)[2]
    psi = q[2] + alpha
    return {"B": b, "C2": d + p.r2 * e(q[1]), "C3": b - p.r3 * e(q[2]), "tip": b + p.L3 * e(psi), "psi": psi}


def to_base(xy: np.ndarray) -> np.ndarray:
    return np.array([xy[0], 0.0, -xy[1]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def node_joint_positions(p: FingerParams, q, prefix: str = "") -> dict[str, float]:
    """What finger_node publishes on joint_states for state q (ros/conversions.joint_state)."""
    pos = joints.joint_positions(tuple(q), kinematics.extended_pose(p), kinematics.distal_offset(p))
    return {prefix + name: value for name, value in zip(joints.JOINT_NAMES, pos)}


def check_state(robot: yourdfpy.URDF, p: FingerParams, q, prefix: str = "", base: np.ndarray | None = None) -> None:
    """FK at the node's joint positions: tip position and orientation, and both halves of pin C."""
    robot.update_cfg(node_joint_positions(p, q, prefix))
    base = np.eye(4) if base is None else base
    pts = model_points(p, q)
    tip = robot.get_transform(prefix + "fingertip")
    np.testing.assert_allclose(tip[:3, 3], base[:3, :3] @ to_base(pts["tip"]) + base[:3, 3], rtol=0, atol=TOL)
    np.testing.assert_allclose(tip[:3, :3], base[:3, :3] @ rot_y(pts["psi"]), rtol=0, atol=TOL)
    # what the node publishes as fingertip_pose (ros/conversions.fingertip_pose)
    pose = kinematics.fingertip(p, tuple(q), kinematics.distal_offset(p))
    np.testing.assert_allclose(tip[:3, 3], base[:3, :3] @ to_base(np.array(pose[:2])) + base[:3, 3], rtol=0, atol=TOL)
    coupler_end = robot.get_transform(prefix + "coupler_pin")[:3, 3]
    distal_pin = robot.get_transform(prefix + "distal_pin")[:3, 3]
    np.testing.assert_allclose(coupler_end, distal_pin, rtol=0, atol=TOL)
    np.testing.assert_allclose(coupler_end, base[:3, :3] @ to_base(pts["C2"]) + base[:3, 3], rtol=0, atol=TOL)
    np.testing.assert_allclose(distal_pin, base[:3, :3] @ to_base(pts["C3"]) + base[:3, 3], rtol=0, atol=TOL)


@pytest.fixture(scope="module")
def robot() -> yourdfpy.URDF:
    return load(finger_urdf(P))


@pytest.fixture(scope="module")
def toggle_run():
    """The paper's ramp through the toggle (config/toggle_passage.yaml), every step."""
    return simulate(load_scene(ref.CONFIG / "toggle_passage.yaml"))


# -- structure ----------------------------------------------------------------------------
def test_links_joints_and_conventions(robot):
    assert robot.validate(), robot.errors
    assert robot.base_link == "finger_base"
    assert set(LINKS) <= set(robot.link_map)
    expected = {"mcp_joint": ("finger_base", "proximal_link"), "pip_joint": ("proximal_link", "distal_link"),
                "coupler_joint": ("finger_base", "coupler_link")}
    for name, (parent, child) in expected.items():
        j = robot.joint_map[name]
        assert (j.type, j.parent, j.child) == ("revolute", parent, child)
        np.testing.assert_array_equal(j.axis, [0.0, 1.0, 0.0])
    assert robot.joint_map["fingertip_joint"].type == "fixed"
    assert robot.joint_map["fingertip_joint"].parent == "distal_link"
    # mcp_joint spans the assemblable range, toggle to toggle (spec §1: −160.3615° .. 104.2116°)
    limit = robot.joint_map["mcp_joint"].limit
    assert (limit.lower, limit.upper) == pytest.approx(ref.toggles()[::-1], abs=1e-12)
    assert limit.effort == MCP_EFFORT_LIMIT
    # A, B, D where spec §1 puts them (extended pose): joint origins in their parents
    np.testing.assert_allclose(robot.joint_map["coupler_joint"].origin[:3, 3], to_base(ref.D), rtol=0, atol=TOL)
    np.testing.assert_allclose(robot.joint_map["pip_joint"].origin[:3, 3], [P.r1, 0.0, 0.0], rtol=0, atol=0)


def test_the_closing_pin_is_documented_in_the_file():
    root = ET.fromstring(finger_urdf(P), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    doc = " ".join(c.text for c in root.iter() if c.tag is ET.Comment)
    for words in ("CLOSED LOOP", "not a joint", "coupler_pin", "distal_pin", "joint_states"):
        assert words in doc


def test_masses_and_inertias_follow_spec_section_2(robot):
    """Uniform slender rods: masses of paper Table II; about the joint axis (y) at the link's
    pivot, I_A = m1 r1²/3 and I_D = m2 r2²/3; the distal link I_G3 = m3 L3²/12 at its centre."""
    rods = {"proximal_link": (ref.M1, ref.R1, ref.I_A), "coupler_link": (ref.M2, ref.R2, ref.I_D),
            "distal_link": (ref.M3, ref.L3, ref.I_G3 + ref.M3 * (ref.L3 / 2) ** 2)}
    for link, (mass, length, about_pivot) in rods.items():
        inertial = robot.link_map[link].inertial
        assert inertial.mass == pytest.approx(mass, rel=1e-15)
        com = inertial.origin[:3, 3]
        np.testing.assert_allclose(com, [length / 2, 0.0, 0.0], rtol=0, atol=1e-18)
        i_com = inertial.inertia
        # parallel-axis theorem back to the link's pivot
        assert i_com[1, 1] + mass * (length / 2) ** 2 == pytest.approx(about_pivot, rel=1e-14)
        assert i_com[2, 2] == i_com[1, 1] and 0.0 < i_com[0, 0] < 1e-5 * i_com[1, 1]
        assert np.all(np.linalg.eigvalsh(i_com) > 0.0)
    assert sum(robot.link_map[n].inertial is not None for n in robot.link_map) == 3


def test_capsules_per_spec_section_7(robot):
    for link, (radius, length) in {"proximal_link": (PHALANX_RADII[0], P.r1), "distal_link": (PHALANX_RADII[1], P.L3)}.items():
        shapes = robot.link_map[link].collisions
        cyl = [c for c in shapes if c.geometry.cylinder is not None]
        spheres = sorted(c.origin[0, 3] for c in shapes if c.geometry.sphere is not None)
        assert len(cyl) == 1 and cyl[0].geometry.cylinder.radius == radius and cyl[0].geometry.cylinder.length == length
        # the cylinder's axis (its local z) lies along the link's x, from 0 to length
        np.testing.assert_allclose(cyl[0].origin[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=1e-15)
        assert spheres == pytest.approx([0.0, length], abs=1e-18)
    assert not robot.link_map["coupler_link"].collisions  # inside the finger, touches nothing (spec §7)


# -- forward kinematics at the node's joint states -----------------------------------------
def test_fk_matches_the_model_over_the_toggle_run(robot, toggle_run):
    """Every 25th step of the ramp through the toggle, the step nearest the toggle (θ1 ≈ 104.2°),
    and the other branch after it."""
    q = toggle_run.q
    near = int(np.argmax(q[:, 0]))
    assert math.degrees(q[near, 0]) == pytest.approx(ref.TOGGLES_DEG[0], abs=1e-2)
    # the spec's branch has sin(θ3 − θ2) < 0; past the toggle the linkage runs on the other one
    other = np.flatnonzero(np.sin(q[:, 2] - q[:, 1]) > 0.0)
    assert len(other) > 100
    for k in sorted({*range(0, len(q), 25), near, int(np.argmax(q[:, 0] * (q[:, 0] < q[near, 0] - 1e-3))), *other[::25]}):
        check_state(robot, P, q[k])


@pytest.mark.parametrize("theta1_deg", [0.0, 34.34, 90.0, 104.2, 104.2116, -90.0, -160.3])
@pytest.mark.parametrize("branch", [+1, -1])
def test_fk_matches_the_independent_assembly(robot, theta1_deg, branch):
    q = kinematics.assemble(P, math.radians(theta1_deg), branch)
    check_state(robot, P, q)
    if branch == +1 and abs(theta1_deg) < 104.0:  # reference.py's Newton continuation: the spec's branch
        q_ref = ref.assemble(math.radians(theta1_deg))
        np.testing.assert_allclose(to_base(model_points(P, q_ref)["tip"]), to_base(ref.tip(q_ref)), rtol=0, atol=TOL)
        robot.update_cfg(node_joint_positions(P, q_ref))
        np.testing.assert_allclose(robot.get_transform("fingertip")[:3, 3], to_base(ref.tip(q_ref)), rtol=0, atol=TOL)


def test_at_zero_joint_positions_the_finger_is_extended(robot):
    robot.update_cfg({name: 0.0 for name in joints.JOINT_NAMES})
    np.testing.assert_allclose(robot.get_transform("fingertip")[:3, 3], [P.r1 + P.L3, 0.0, 0.0], rtol=0, atol=TOL)
    # positive mcp flexes towards the palm (−z, spec §6: model Y is −z)
    robot.update_cfg({"mcp_joint": 0.1, "coupler_joint": 0.0, "pip_joint": 0.0})
    assert robot.get_transform("fingertip")[2, 3] < 0.0


# -- other geometry, prefixes, hands ----------------------------------------------------
def test_a_scene_with_other_geometry_gets_a_matching_urdf(tmp_path):
    scene_file = tmp_path / "long.yaml"
    scene_file.write_text(yaml.safe_dump({"model": {"geometry": {"r1": 0.05, "L3": 0.03, "m3": 0.01}},
                                          "input": {"torque": {"type": "constant", "value": 0.002}},
                                          "duration": 0.2, "integrator": {"method": "rk6", "dt": 0.001}}))
    scene = load_scene(scene_file)
    robot = load(finger_urdf(scene.params))
    assert robot.link_map["distal_link"].inertial.mass == 0.01
    assert robot.joint_map["pip_joint"].origin[0, 3] == 0.05
    lo, hi = kinematics.assembly_range(scene.params)
    assert (robot.joint_map["mcp_joint"].limit.lower, robot.joint_map["mcp_joint"].limit.upper) == (lo, hi)
    traj = simulate(scene)
    for k in range(0, len(traj.q), 20):
        check_state(robot, scene.params, traj.q[k])
    # the CLI writes the same description
    out = tmp_path / "long.urdf"
    assert cli(["urdf", str(scene_file), "-o", str(out)]) == 0
    assert out.read_text() == finger_urdf(scene.params)


def test_a_crank_that_turns_fully_gets_a_continuous_mcp_joint():
    """r1 − r4 ≥ r2 − r3 and r1 + r4 ≤ r2 + r3: the coupler dyad reaches B at every MCP angle."""
    p = FingerParams(r3=0.012)
    assert kinematics.assembly_range(p) == (-math.inf, math.inf)
    robot = load(finger_urdf(p))
    assert robot.joint_map["mcp_joint"].type == "continuous"
    for theta1 in (0.0, 1.0, 2.5, 4.0, 6.0):
        check_state(robot, p, kinematics.assemble(p, theta1))


def test_prefix_names_every_link_and_joint():
    robot = load(finger_urdf(P, prefix="index_"))
    assert all(name.startswith("index_") for name in [*robot.link_map, *robot.joint_map])
    assert robot.base_link == "index_finger_base"
    check_state(robot, P, kinematics.assemble(P, 0.7), prefix="index_")


def test_hand_joins_fingers_under_hand_base():
    small = FingerParams(r1=0.045, L3=0.035, m3=0.012)
    poses = {"index_": (0.01, 0.02, 0.0, 0.0, 0.0, 0.1), "middle_": (0.012, 0.0, 0.001, 0.2, -0.3, 0.0),
             "little_": (0.005, -0.03, -0.002, 0.0, 0.1, -0.2)}
    params = {"index_": P, "middle_": P, "little_": small}
    robot = load(hand_urdf([(k, params[k], poses[k]) for k in poses]))
    assert robot.validate(), robot.errors
    assert robot.base_link == "hand_base"
    for prefix, pose in poses.items():
        mount = robot.get_transform(prefix + "finger_base")
        # the base pose, composed independently: URDF rpy is fixed-axis x, y, z (R = Rz Ry Rx)
        cr, sr, cp, sp, cy, sy = (f(a) for a in pose[3:] for f in (math.cos, math.sin))
        rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        np.testing.assert_allclose(mount[:3, :3], rz @ rot_y(pose[4]) @ rx, rtol=0, atol=1e-15)
        np.testing.assert_allclose(mount[:3, 3], pose[:3], rtol=0, atol=0)
        check_state(robot, params[prefix], kinematics.assemble(params[prefix], 0.5), prefix, mount)


@pytest.mark.parametrize("call, key", [
    (lambda: finger_urdf(P, prefix="my finger"), "prefix"),
    (lambda: finger_urdf(P, radii=(0.008, 0.0)), "radii"),
    (lambda: finger_urdf(P, mcp_effort=math.nan), "mcp_effort"),
    (lambda: hand_urdf([("a_", P, (0, 0, 0, 0, 0, 0)), ("a_", P, (0, 0, 0, 0, 0, 0))]), "fingers.prefix"),
    (lambda: hand_urdf([("a_", P, (0, 0, 0))]), "pose"),
    (lambda: hand_urdf([]), "fingers"),
])
def test_bad_arguments_are_refused_by_name(call, key):
    with pytest.raises(ConfigError, match=key):
        call()


# -- the installed copy and the ros2_control example -----------------------------------
def test_the_installed_copy_is_the_generators_output_for_the_default_scene():
    default = load_scene(ref.CONFIG / "finger_default.yaml")
    assert default.params == FingerParams()
    assert INSTALLED.read_text() == finger_urdf(FingerParams(), mcp_limits=default.mcp_limits)


def limit(robot_xml: str, joint: str) -> tuple[float, float, float, float]:
    element = ET.fromstring(robot_xml.split("\n", 1)[1]).find(f"joint[@name='{joint}']/limit")
    return tuple(float(element.get(k)) for k in ("lower", "upper", "effort", "velocity"))


def test_limits_are_the_scenes_stops_and_the_loops_ranges():
    """issue 19, item 4: mcp_joint's limits are the scene's stops (θ1 − θ1_ext), not the toggles;
    the passive joints' are the range the loop gives them over it (an independent sweep of the
    closed-form assembly, spec §6's joint formulas written out here); placeholders are labelled."""
    scene = load_scene(ref.CONFIG / "finger_default.yaml")
    p = scene.params
    text = finger_urdf(p, mcp_limits=scene.mcp_limits, mcp_effort=0.03)
    ext = kinematics.extended_pose(p)
    lower, upper, effort, _ = limit(text, "mcp_joint")
    assert (lower, upper, effort) == (scene.mcp_limits[0] - ext[0], scene.mcp_limits[1] - ext[0], 0.03)
    alpha = ext[0] - ext[2]
    sweep = np.linspace(*scene.mcp_limits, 20_001)
    poses = np.array([kinematics.assemble(p, t) for t in sweep])
    coupler = poses[:, 1] - ext[1]  # θ2 − θ2_ext
    pip = poses[:, 2] + alpha - poses[:, 0]  # β = ψ − θ1, ψ = θ3 + α
    for joint, values in (("coupler_joint", coupler), ("pip_joint", pip)):
        lo, hi, eff, _ = limit(text, joint)
        assert eff == 0.0
        assert lo <= values.min() + 1e-12 and hi >= values.max() - 1e-12, joint  # every pose inside
        assert values.min() - lo < 1e-6 and hi - values.max() < 1e-6, joint  # and no wider than the sweep
    assert text.count("is a placeholder: the model has no speed limit") == 3
    assert "limits: the scene's MCP stops (joint_limits.mcp)" in text
    # without stops: toggle to toggle, said so
    lo, hi = kinematics.assembly_range(p)
    assert limit(finger_urdf(p), "mcp_joint")[:2] == (lo - ext[0], hi - ext[0])
    assert "the linkage's assembly range (toggle to toggle); no MCP stops" in finger_urdf(p)


#: spec §8's default drive (its parameter table), SI: R Ω, k_t N·m/A, u_max V, i_max A, N, η_f
SPEC_DRIVE = dict(resistance=8.0, torque_constant=4.0e-3, supply_voltage=6.0, current_limit=0.5, gear_ratio=300.0,
                  efficiency=0.4)


@pytest.mark.parametrize("scene_name", ["drive_grasp", "drive_grasp_backdrivable"])
def test_a_drive_gives_mcp_joint_its_speed_and_torque_limits(scene_name, capsys):
    """issue 19, item 4: with a drive, mcp_joint's velocity limit is the no-load speed
    u_max/(k_e N) and its effort limit the stall torque η_f N k_t i_max (spec §8; k_e = k_t in
    SI), from the scene file's own drive values over the spec's defaults; no placeholder on it."""
    path = ref.CONFIG / f"{scene_name}.yaml"
    d = {**SPEC_DRIVE, **yaml.safe_load(path.read_text())["model"]["drive"]}
    speed = d["supply_voltage"] / (d["torque_constant"] * d["gear_ratio"])
    stall = d["efficiency"] * d["gear_ratio"] * d["torque_constant"] * d["current_limit"]
    assert cli(["urdf", str(path)]) == 0
    text = capsys.readouterr().out
    _, _, effort, velocity = limit(text, "mcp_joint")
    assert velocity == pytest.approx(speed, rel=1e-15) and effort == pytest.approx(stall, rel=1e-15)
    if scene_name == "drive_grasp":  # spec §8's derived figures at the defaults
        assert (velocity, effort) == (pytest.approx(5.0, rel=1e-15), pytest.approx(0.24, rel=1e-15))
    assert text.count("is a placeholder") == 2  # the passive joints' velocity only
    assert "no-load speed u_max / (k_e N)" in text and "stall torque eta_f N k_t i_max" in text
    # a hand of such a finger: the same limits on its prefixed mcp_joint
    scene = load_scene(path)
    hand = hand_urdf([("a_", scene.params, (0.0,) * 6, scene.mcp_limits, scene.drive)])
    assert limit(hand, "a_mcp_joint")[2:] == (effort, velocity)


def test_cli_prints_the_urdf_of_a_scene(capsys):
    assert cli(["urdf", str(ref.CONFIG / "paper_flexion.yaml"), "--prefix", "thumb_"]) == 0
    limits = load_scene(ref.CONFIG / "paper_flexion.yaml").mcp_limits
    assert capsys.readouterr().out == finger_urdf(P, prefix="thumb_", mcp_limits=limits)
    assert cli(["urdf", str(ref.CONFIG / "paper_flexion.yaml"), "--prefix", "a b"]) == 2
    assert "prefix" in capsys.readouterr().err


def test_ros2_control_example_actuates_effort_on_mcp_joint_only():
    block = ET.parse(ROS2_CONTROL / "finger.ros2_control.xml").getroot()
    assert block.tag == "ros2_control"
    hardware = block.find("hardware")
    assert hardware.findtext("plugin").strip() == "joint_state_topic_hardware_interface/JointStateTopicSystem"
    params = {p.get("name"): p.text for p in hardware.findall("param")}
    assert params["joint_commands_topic"] == "/joint_command" and params["joint_states_topic"] == "/joint_states"
    # Every cycle sends the command: the plugin skips a write when the positions barely differ,
    # which with effort commands (no position command) would be whenever mcp_joint is near 0.
    assert float(params["trigger_joint_command_threshold"]) < 0.0
    (joint,) = block.findall("joint")
    assert joint.get("name") == "mcp_joint"
    assert [c.get("name") for c in joint.findall("command_interface")] == ["effort"]
    # pasted into the finger's URDF, it is still a URDF an independent reader accepts
    robot = ET.fromstring(finger_urdf(P).split("\n", 1)[1])
    robot.append(block)
    assert load(ET.tostring(robot, encoding="unicode")).validate()

    config = yaml.safe_load((ROS2_CONTROL / "finger_controllers.yaml").read_text())
    cm = config["controller_manager"]["ros__parameters"]
    assert cm["joint_state_broadcaster"]["type"] == "joint_state_broadcaster/JointStateBroadcaster"
    name = next(k for k, v in cm.items() if isinstance(v, dict) and v.get("type") == "forward_command_controller/ForwardCommandController")
    assert config[name]["ros__parameters"] == {"joints": ["mcp_joint"], "interface_name": "effort"}
    # the broadcaster must not publish on the node's own joint_states
    assert config["joint_state_broadcaster"]["ros__parameters"]["use_local_topics"] is True
