"""Actuators: what turns the scene's input into a generalized force on link 1.

Without `model.drive` the input is the motor torque τ (N·m) and the ideal torque source of
spec §3 applies it as it is: no actuator object exists and nothing costs anything. With
`model.drive` (spec §8) the input is the terminal voltage command u (V) and the drive
(`finger_sim.actuators.drive`) owns the mesh's discrete mode (drive / back / stuck), its
guards and its outputs; `finger_sim.actuators.stepping` locates its mode changes inside the
step. The scene's input profile (`Scene.torque`) is then read as volts. With an inductance
L > 0 the winding current is the drive's own state (`Drive.i`), carried through the integrator's
stages by `finger_sim.actuators.inductive` and stepped by `finger_sim.actuators.inductive_stepping`.
"""

from finger_sim.actuators.drive import Drive, DriveParams, DrivenSystem, drive_from_dict

__all__ = ["Drive", "DriveParams", "DrivenSystem", "drive_from_dict"]
