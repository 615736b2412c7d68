"""Actuators: what turns the scene's input into a generalized force on link 1.

The slot (`finger_sim.actuators.base.Actuator`) declares its input, its own continuous state (slots in
the flat state, `finger_sim.state_layout`) and its modes; `Simulator(scene, actuator=...)` steps one
(`finger_sim.integrators.stateful`), on the compiled kernel where it declares its law (`ActuatorLaw`,
`LawActuator`: plain functions that the kernel compiles, `finger_sim.kernel.stateful`).

Without `model.drive` the input is the motor torque τ (N·m) and the ideal torque source of
spec §3 applies it as it is: no actuator object exists and nothing costs anything. With
`model.drive` (spec §8) the input is the terminal voltage command u (V) and the drive
(`finger_sim.actuators.drive`) owns the mesh's discrete mode (drive / back / stuck), its
guards and its outputs; `finger_sim.actuators.stepping` locates its mode changes inside the
step. The scene's input profile (`Scene.torque`) is then read as volts. With an inductance
L > 0 the winding current is the drive's declared slot (`Drive.slots`, kept in `Drive.i`), carried
through the stages by `integrators.stateful` and its events located by `actuators.inductive_stepping`.
"""

from finger_sim.actuators.base import Actuator, ActuatorLaw, LawActuator
from finger_sim.actuators.drive import Drive, DriveParams, DrivenSystem, drive_from_dict

__all__ = ["Actuator", "ActuatorLaw", "Drive", "DriveParams", "DrivenSystem", "LawActuator", "drive_from_dict"]
