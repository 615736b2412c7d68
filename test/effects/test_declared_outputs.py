"""Outputs declared once per effect and actuator (`effects.base.Output`): what the elements report is what
they declare, in the declared order; the CSV headers, the node's topics and the task runner's columns are
the ones main had before the declarations (recorded from main at ca9e264, below), and the names are
spelled nowhere else in the package."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

from finger_sim.actuators.drive_outputs import DRIVE_OUTPUTS
from finger_sim.cli import main
from finger_sim.effects import EFFECTS, declared_outputs
from finger_sim.effects.contact_outputs import CONTACT_OUTPUTS, GRIP_FORCE
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, output_names

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}
#: Scenes that between them report every declared output: contact, stick-slip, a moving object, a drive
#: with an encoder and every sensor.
SCENES = {
    "grasp_cylinder": load_scene(CONFIG / "grasp_cylinder.yaml"),
    "drive_grasp": load_scene(CONFIG / "drive_grasp.yaml"),
    "hold_table": load_scene(CONFIG / "friction" / "hold_table.yaml"),
    "drive_sensed": scene_from_dict({
        "model": {"drive": {"encoder_counts": 512}}, "objects": [CUP], "input": {"voltage": {"type": "constant", "value": 6.0}},
        "duration": 0.02, "sensors": {"seed": 1, "motor_current": {"noise": 0.001}, "encoder": {},
                                      "fsr_proximal": {"noise": 0.01}, "fsr_distal": {}}}),
    "pushed": scene_from_dict({
        "objects": [{**CUP, "motion": {"type": "push", "direction": [0.0, -1.0], "distance": 0.001, "start": 0.005,
                                       "duration": 0.01}}],
        "input": {"torque": {"type": "constant", "value": 0.02}}, "duration": 0.02}),
}
CONTACT = ("grip_force,contact_force_proximal_x,contact_force_proximal_y,contact_force_distal_x,contact_force_distal_y")
#: `finger-sim simulate --csv` headers after the state columns, as main wrote them before the declarations.
MAIN_HEADERS = {
    "grasp_cylinder": CONTACT,
    "drive_grasp": CONTACT + ",motor_voltage,motor_current,motor_angle,mesh_mode,mesh_loss,mesh_torque",
    "hold_table": CONTACT + ",friction_mode,friction_torque,friction_power",
    "drive_sensed": CONTACT + ",motor_voltage,motor_current,motor_angle,encoder,mesh_mode,mesh_loss,mesh_torque,"
                              "fsr_proximal,fsr_distal,motor_current_measured,encoder_measured,fsr_proximal_measured,"
                              "fsr_distal_measured",
    "pushed": CONTACT + ",motion_power",
}
STATE = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"
#: finger_node's output topics as main published them: key → (topic, message type, the output that enables it).
MAIN_TOPICS = {
    "grip_force": ("grip_force", "std_msgs/msg/Float64", "grip_force"),
    "grip_force_stamped": ("grip_force_stamped", "geometry_msgs/msg/WrenchStamped", "grip_force"),
    "contact_wrench/proximal": ("contact_wrench/proximal", "geometry_msgs/msg/WrenchStamped", "grip_force"),
    "contact_wrench/distal": ("contact_wrench/distal", "geometry_msgs/msg/WrenchStamped", "grip_force"),
    "motor/current": ("motor/current", "std_msgs/msg/Float64", "motor_current"),
    "motor/voltage": ("motor/voltage", "std_msgs/msg/Float64", "motor_current"),
    "motor/angle": ("motor/angle", "std_msgs/msg/Float64", "motor_current"),
    "motor/encoder": ("motor/encoder", "std_msgs/msg/Int64", "encoder"),
    "motor/mesh_mode": ("motor/mesh_mode", "std_msgs/msg/String", "motor_current"),
}


def reported(name: str) -> list[str]:
    """The names a scene's elements report at its start, then its drive's, in order."""
    sim = Simulator(SCENES[name])
    names = list(output_names(sim.system.elements, sim.q))
    if SCENES[name].drive is not None:
        names += sim.system.output_names()
        assert list(sim.system.motor_outputs(0.0, sim.q, sim.v, 0.0)) == list(sim.system.output_names())
    return names


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_element_reports_only_what_it_declares_in_the_declared_order(name: str) -> None:
    names = reported(name)
    declared = [o.name for o in (*CONTACT_OUTPUTS, *DRIVE_OUTPUTS)]
    assert set(names) <= set(declared)
    assert names == sorted(names, key=declared.index)
    assert ",".join(names) == MAIN_HEADERS[name].split(",fsr_")[0]  # the sensors' columns come after


def test_each_output_is_declared_once_and_the_registry_holds_the_contact_ones() -> None:
    everything = [*(o for e in EFFECTS.values() for o in e.outputs), *DRIVE_OUTPUTS]
    assert len({o.name for o in everything}) == len(everything)
    assert EFFECTS["contact"].outputs == CONTACT_OUTPUTS and declared_outputs()["grip_force"] is GRIP_FORCE
    assert {o.name for o in everything if not o.measurable} == {
        "motion_power", "contact_force_proximal_x", "contact_force_proximal_y", "contact_force_distal_x",
        "contact_force_distal_y"}  # main's task runner withheld these from the controller


@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_csv_header_is_main_s(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene_file = tmp_path / f"{name}.yaml"
    scene_file.write_text(SCENES[name].to_yaml(), encoding="utf-8")
    out = tmp_path / "run.csv"
    assert main(["simulate", str(scene_file), "--t-end", "0.01", "--csv", str(out)]) == 0
    with out.open(encoding="utf-8") as f:
        header = next(csv.reader(f))
    assert ",".join(header) == f"{STATE},{MAIN_HEADERS[name]}"


def test_the_task_runner_columns_are_main_s() -> None:
    from finger_sim.tasks.controllers import MEASURED
    from finger_sim.tasks.runner import COLUMNS, DRIVE_COLUMNS, UNMEASURED

    assert COLUMNS == ("t", "grip_force", "setpoint", "theta1", "theta1_dot", "command", "tip_force_x", "tip_force_y",
                       "crushed")
    assert DRIVE_COLUMNS == ("motor_voltage", "motor_current") and MEASURED == ("grip_force", "theta1", "theta1_dot")
    assert UNMEASURED == {"motion_power", "contact_force_proximal_x", "contact_force_proximal_y",
                          "contact_force_distal_x", "contact_force_distal_y"}


def test_the_node_topics_are_main_s_and_carry_the_declared_message_types() -> None:
    pytest.importorskip("rclpy")
    from finger_sim.ros.interfaces import OUTPUTS

    def type_name(cls: type) -> str:
        return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"

    got = {k: (OUTPUTS[k].topic, type_name(OUTPUTS[k].msg_type), OUTPUTS[k].reported_by) for k in MAIN_TOPICS}
    assert got == MAIN_TOPICS
    for output in (*CONTACT_OUTPUTS, *DRIVE_OUTPUTS):
        if output.topic is not None:
            assert type_name(OUTPUTS[output.topic].msg_type) == output.message, output.name


def test_grip_force_is_spelled_once_in_the_package() -> None:
    """The output names appear as string literals only in their declarations (docstrings and help texts may
    mention them)."""
    literal = re.compile(r"""(?<![\w/])["'](grip_force|contact_force_\w+|motion_power|mesh_torque|friction_mode)["']""")
    spelled = sorted(f"{p.relative_to(ROOT)}:{m.group(1)}" for p in (ROOT / "finger_sim").rglob("*.py")
                     for m in literal.finditer(p.read_text(encoding="utf-8")))
    assert spelled == ["finger_sim/actuators/drive_outputs.py:mesh_torque",
                       "finger_sim/effects/contact_outputs.py:friction_mode",
                       "finger_sim/effects/contact_outputs.py:grip_force",
                       "finger_sim/effects/contact_outputs.py:grip_force",  # the output and its topic
                       "finger_sim/effects/contact_outputs.py:motion_power"]
