"""The drive's state as messages (spec §8): what a prosthetic controller reads from the device.

Topics (per finger, published at the state rate and logged): `motor/current` (A), `motor/voltage`
(terminal voltage, V), `motor/angle` (rad at the motor), `motor/encoder` (counts, std_msgs/Int64;
only with encoder_counts > 0) and `motor/mesh_mode` (`drive`, `back`, `stuck`).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from std_msgs.msg import Float64, Int64, String

from finger_sim.actuators.drive import MESH_MODES, DrivenSystem
from finger_sim.simulate import Simulator

#: OUTPUTS key → the drive output it carries.
FLOAT_TOPICS = {"motor/current": "motor_current", "motor/voltage": "motor_voltage", "motor/angle": "motor_angle"}


def motor_state(sim: Simulator) -> dict[str, float]:
    """The drive's outputs at the simulator's state under the input of the step that ended there."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    return system.motor_outputs(sim.time, sim.q, sim.v, sim.torque)


def messages(state: dict[str, float]) -> Iterator[tuple[str, Any]]:
    """(OUTPUTS key, message) for each motor topic of one state (`motor_state`)."""
    for key, name in FLOAT_TOPICS.items():
        yield key, Float64(data=float(state[name]))
    if "encoder" in state:
        yield "motor/encoder", Int64(data=int(state["encoder"]))
    yield "motor/mesh_mode", String(data=MESH_MODES[int(state["mesh_mode"])])
