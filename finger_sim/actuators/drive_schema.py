"""The drive's scene keys (`model.drive`, spec §8) as a pydantic model, with `drive_from_dict`'s bounds
and `DriveParams`' defaults, so an editor refuses what the loader refuses. `backward_efficiency`'s default
follows `efficiency` (2 − 1/η_f, a worm-type train), which a schema can only state in words."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from finger_sim.actuators.drive import (MAX_CURRENT_LIMIT, MAX_ENCODER_COUNTS, MAX_GEAR_RATIO, MAX_INDUCTANCE,
                                        MAX_RESISTANCE, MAX_ROTOR_INERTIA, MAX_SUPPLY_VOLTAGE, MAX_TORQUE_CONSTANT,
                                        MIN_BACKWARD_EFFICIENCY, DriveParams)
from finger_sim.effects.parameters import bounded, whole

_D = DriveParams()


class DriveSchema(BaseModel):
    """`model.drive`: a DC motor behind a lossy, possibly self-locking gear train ({} = spec §8's defaults)."""

    model_config = ConfigDict(extra="forbid", title="Drive")
    resistance: bounded("winding resistance R (Ω)", minimum=0.0, maximum=MAX_RESISTANCE, strict=True,
                        default=_D.resistance)
    torque_constant: bounded("torque constant k_t = back-EMF constant k_e (N·m/A)", minimum=0.0,
                             maximum=MAX_TORQUE_CONSTANT, strict=True, default=_D.torque_constant)
    rotor_inertia: bounded("rotor inertia J_m (kg·m²)", minimum=0.0, maximum=MAX_ROTOR_INERTIA, strict=True,
                           default=_D.rotor_inertia)
    inductance: bounded("winding inductance L (H); 0: the current follows the voltage at once", minimum=0.0,
                        maximum=MAX_INDUCTANCE, default=_D.inductance)
    supply_voltage: bounded("supply voltage: the command saturates at ± this (V)", minimum=0.0,
                            maximum=MAX_SUPPLY_VOLTAGE, strict=True, default=_D.supply_voltage)
    current_limit: bounded("driver's current limit i_max (A)", minimum=0.0, maximum=MAX_CURRENT_LIMIT, strict=True,
                           default=_D.current_limit)
    gear_ratio: bounded("gear ratio N (motor turns per turn of θ1)", minimum=0.0, maximum=MAX_GEAR_RATIO,
                        strict=True, default=_D.gear_ratio)
    efficiency: bounded("forward mesh efficiency η_f", minimum=0.0, maximum=1.0, strict=True, default=_D.efficiency)
    backward_efficiency: bounded("backward mesh efficiency η_b (≤ 0: self-locking; default 2 − 1/efficiency)",
                                 minimum=MIN_BACKWARD_EFFICIENCY, maximum=1.0, default=_D.backward_efficiency)
    encoder_counts: whole("encoder counts per motor turn (0: no encoder)", 0, MAX_ENCODER_COUNTS,
                          default=_D.encoder_counts)
