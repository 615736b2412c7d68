"""Commands of a finger with a drive (spec §8): the voltage on `motor_voltage`, the torque topics refused.

A finger with `model.drive` is commanded by its terminal voltage (V): held, saturated at the
drive's supply voltage (not at max_torque), dropped to 0 after command_timeout, with the same
events as a torque (`TorqueCommands`, whose `torque` field then carries volts). A torque-driven
finger refuses `motor_voltage`; a driven one refuses `motor_torque`, `effort_commands` and
`joint_command`, each with a reason that names the topic to use.
"""

from __future__ import annotations

from finger_sim.actuators.drive import DriveParams
from finger_sim.runtime.commands import TorqueCommands
from finger_sim.runtime.timeline import Timeline

#: The command topic of a finger with a drive (std_msgs/Float64, V).
VOLTAGE_TOPIC = "motor_voltage"
REFUSED_TORQUE = ("this finger has a drive (model.drive): its command is the voltage on motor_voltage "
                  "(std_msgs/Float64, V), not a torque")
REFUSED_VOLTAGE = "this finger has no drive (model.drive): its command is the torque on motor_torque (N·m), not a voltage"


def input_refusal(topic: str, driven: bool) -> str | None:
    """Why a command on `topic` (an InputSpec's topic) is refused for this finger, or None."""
    if driven and topic != VOLTAGE_TOPIC:
        return REFUSED_TORQUE
    if not driven and topic == VOLTAGE_TOPIC:
        return REFUSED_VOLTAGE
    return None


class VoltageCommands(TorqueCommands):
    """TorqueCommands whose held value is the voltage command, saturated at ±supply_voltage (V);
    the max_torque parameter does not apply to it."""

    def __init__(self, timeline: Timeline, drive: DriveParams, *, command_timeout: float, accepting: bool) -> None:
        super().__init__(timeline, max_torque=drive.supply_voltage, command_timeout=command_timeout, accepting=accepting)

    def set_max_torque(self, limit: float) -> None:
        """max_torque limits a torque; a voltage stays saturated at the supply."""
