"""Objects crushed in a node's run: the offline rule (finger_sim.grasp_objects) applied after every step.

An object with a `break_force` (N) is crushed at the end of the first step at which the normal
force on it exceeds that force, and taken out of the scene from the next step on: the same rule,
the same code (`crush_step`) and so the same states as the task runner and `resim`. The state at
the crush keeps the force that broke it (its contact topics show it), the states after show the
scene without the object.

Each crush is a record (`Crush.to_values`, key → text, floats as repr so they read back exactly)
on the finger's `~/crush_log` topic (diagnostic_msgs/DiagnosticStatus, logged) and a warning in
the node's log; /diagnostics counts them. A reset restores the scene with every object.

Plain Python over a Simulator: no rclpy, no messages, no MCAP.
"""

from __future__ import annotations

from finger_sim.grasp_objects import Crush, breakable, crush_step
from finger_sim.simulate import Simulator

#: What a finger with a breakable object reports beside its element outputs: its `~/crush_log` topic.
CRUSH_OUTPUT = "crush_log"
#: The `event` value of a crush record (as CommandEvent's `event` names what a command did).
CRUSH_EVENT = "crushed"


def crush_values(crush: Crush, episode: int) -> dict[str, str]:
    """The key-value record of `crush` in `episode` (floats as repr: exact when read back)."""
    return {"event": CRUSH_EVENT, "object": crush.object, "episode": str(episode), "step": str(crush.step),
            "t": repr(crush.t), "force": repr(crush.force), "break_force": repr(crush.break_force)}


class Crushing:
    """A finger's Simulator and the objects its steps have crushed (this episode).

    `sim` is the Simulator to step next: after a crush a new one, of the scene without the object,
    in the same state (grasp_objects.carry_over). `before` is the Simulator as it ended the last
    step when that step crushed something (its contact element still holds the broken object),
    else None.
    """

    def __init__(self, sim: Simulator) -> None:
        self.initial = sim
        self.sim = sim
        self.watching = breakable(sim.scene)  # no break_force: nothing to check, no cost per step
        self.crushes: list[Crush] = []
        self.before: Simulator | None = None
        self._reported = 0  # crushes already taken by `new`

    def after_step(self) -> None:
        """Check the step just taken; a crushed object is taken out of the scene."""
        self.before = None
        if not self.watching:
            return
        sim, broken = crush_step(self.sim)
        if broken:
            self.before, self.sim = self.sim, sim
            self.crushes += broken
            self.watching = breakable(sim.scene)

    def new(self) -> list[Crush]:
        """The crushes since the last call (each reported once)."""
        fresh = self.crushes[self._reported:]
        self._reported = len(self.crushes)
        return fresh

    def reset(self) -> None:
        """The scene with every object again, at its initial state."""
        self.initial.reset()
        self.sim, self.before = self.initial, None
        self.crushes = []
        self._reported = 0
        self.watching = breakable(self.initial.scene)
