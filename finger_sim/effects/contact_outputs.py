"""What the contact effect reports (spec §7), declared once: the names every CSV, sweep, batch and rollout
column, log export, node topic, task and plot uses (`effects.base.Output`)."""

from __future__ import annotations

from finger_sim.effects.base import Output, Wrench

FLOAT64 = "std_msgs/msg/Float64"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
#: The phalanges in the order of their outputs, and each one's wrench topic.
PHALANGES = ("proximal", "distal")
WRENCH_TOPICS = {p: f"contact_wrench/{p}" for p in PHALANGES}

GRIP_FORCE = Output("grip_force", "N", "Σ F_n: the normal contact force summed over phalanges and objects",
                    "grip_force", FLOAT64)


def _force(phalanx: str, axis: str) -> Output:
    return Output(f"contact_force_{phalanx}_{axis}", "N",
                  f"{axis} of the contact force on the {phalanx} phalanx (model plane, sum over objects)",
                  WRENCH_TOPICS[phalanx], WRENCH_STAMPED, measurable=False)


#: contact force on each phalanx, (x, y) in the model plane: {phalanx: (x output, y output)}
CONTACT_FORCES = {p: (_force(p, "x"), _force(p, "y")) for p in PHALANGES}
#: the contact wrench on each phalanx (its force the outputs above, its moment about A), in `PHALANGES` order
CONTACT_WRENCHES = tuple(Wrench(p, CONTACT_FORCES[p]) for p in PHALANGES)
MOTION_POWER = Output("motion_power", "W", "power the moving objects put into the finger (moving objects only)",
                      measurable=False)
FRICTION_MODE = Output("friction_mode", "1", "stick–slip mode: 1 locked, 0 sliding (friction_model: stick_slip)")
FRICTION_TORQUE = Output("friction_torque", "N·m", "friction torque on θ1: holding torque while locked (stick_slip)")
FRICTION_POWER = Output("friction_power", "W", "power of friction, ≤ 0 (stick_slip)")

#: Every output of the contact element, in the order it reports them.
CONTACT_OUTPUTS = (GRIP_FORCE, *(o for pair in CONTACT_FORCES.values() for o in pair), MOTION_POWER,
                   FRICTION_MODE, FRICTION_TORQUE, FRICTION_POWER)
