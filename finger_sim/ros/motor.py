"""The drive's state as messages (spec §8): what a prosthetic controller reads from the device.

Topics (per finger, published at the state rate and logged): `motor/current` (A), `motor/voltage`
(terminal voltage, V), `motor/angle` (rad at the motor), `motor/encoder` (counts, std_msgs/Int64;
only with encoder_counts > 0) and `motor/mesh_mode` (`drive`, `back`, `stuck`); with a
`sensors.motor_current` in the scene also `motor/current_measured` (A, finger_sim.sensors: the
reading a controller gets, seeded, so a resim publishes the same).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from finger_sim.actuators.drive import MESH_MODES, DrivenSystem
from finger_sim.actuators.drive_outputs import ENCODER, MESH_MODE, MOTOR_ANGLE, MOTOR_CURRENT, MOTOR_VOLTAGE
from finger_sim.log.cdr_writer import float64_cdr, int64_cdr, string_cdr
from finger_sim.scene import Scene
from finger_sim.sensors import SensorBank, SensorSet
from finger_sim.simulate import Simulator

#: OUTPUTS key → the drive output it carries.
FLOAT_TOPICS = {o.topic: o.name for o in (MOTOR_CURRENT, MOTOR_VOLTAGE, MOTOR_ANGLE)}
#: The mesh modes' std_msgs/String messages, as CDR bytes.
MODE_CDR = tuple(string_cdr(name) for name in MESH_MODES)


def motor_state(sim: Simulator) -> dict[str, float]:
    """The drive's outputs at the simulator's state under the input of the step that ended there."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    return system.motor_outputs(sim.time, sim.q, sim.v, sim.torque)


def messages(state: dict[str, float]) -> Iterator[tuple[str, bytes]]:
    """(OUTPUTS key, message as CDR bytes: no message objects, no rclpy serialization at 1 kHz) for each
    motor topic of one state (`motor_state`)."""
    for key, name in FLOAT_TOPICS.items():
        yield key, float64_cdr(float(state[name]))
    if ENCODER.name in state:
        yield ENCODER.topic, int64_cdr(int(state[ENCODER.name]))
    yield MESH_MODE.topic, MODE_CDR[int(state[MESH_MODE.name])]


class CurrentSensor:
    """The scene's `sensors.motor_current` read at the node's publishing times (its noise stream is the
    offline run's: the same seed and sensor); `reset` starts it over with the episode."""

    def __init__(self, scene: Scene, dt: float) -> None:
        sensors: SensorSet = scene.sensors  # type: ignore[assignment]
        self._set = SensorSet(seed=sensors.seed, pairs=(("motor_current", sensors.models["motor_current"]),))
        self._dt = dt
        self.reset()

    @staticmethod
    def wanted(scene: Scene) -> bool:
        return scene.drive is not None and scene.sensors is not None and "motor_current" in scene.sensors.models

    def reset(self) -> None:
        self._bank = SensorBank(self._set, self._dt)
        self._last: int | None = None

    def message(self, step: int, state: dict[str, float]) -> bytes:
        """The reading at the simulator's step (its step_index) of the drive's state (`motor_state`)."""
        elapsed = 0.0 if self._last is None else (step - self._last) * self._dt  # one step: dt exactly, as offline
        self._last = step
        reading = self._bank.measure({MOTOR_CURRENT.name: np.array([state[MOTOR_CURRENT.name]])}, elapsed=elapsed)
        return float64_cdr(float(reading["motor_current_measured"][0]))
