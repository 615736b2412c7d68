"""What the drive reports (spec §8), declared once: the names every CSV, sweep, batch and rollout column,
log export, node topic, task and plot uses (`effects.base.Output`)."""

from __future__ import annotations

from finger_sim.effects.base import Output

FLOAT64 = "std_msgs/msg/Float64"

MOTOR_VOLTAGE = Output("motor_voltage", "V", "terminal voltage v = R i + L i' + k_e N θ1'", "motor/voltage", FLOAT64)
MOTOR_CURRENT = Output("motor_current", "A", "winding current i", "motor/current", FLOAT64)
MOTOR_ANGLE = Output("motor_angle", "rad", "motor shaft angle N θ1", "motor/angle", FLOAT64)
ENCODER = Output("encoder", "counts", "encoder reading ⌊N θ1 / 2π · counts⌋ (with encoder_counts > 0)",
                 "motor/encoder", "std_msgs/msg/Int64")
MESH_MODE = Output("mesh_mode", "1", "mesh mode code: 0 drive, 1 back, 2 stuck", "motor/mesh_mode",
                   "std_msgs/msg/String")
MESH_LOSS = Output("mesh_loss", "W", "power lost in the gear mesh")
MESH_TORQUE = Output("mesh_torque", "N·m", "torque τ_g the mesh puts on link 1")

#: Every output of the drive, in the order it reports them (the encoder only with encoder_counts > 0).
DRIVE_OUTPUTS = (MOTOR_VOLTAGE, MOTOR_CURRENT, MOTOR_ANGLE, ENCODER, MESH_MODE, MESH_LOSS, MESH_TORQUE)
