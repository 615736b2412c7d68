"""Objects crushed in a node's run: the record of each crush.

An object with a `break_force` (N) is crushed at the end of the first step at which the normal
force on it exceeds that force, and taken out of the scene from the next step on: the offline rule
(finger_sim.grasp_objects), applied by the same code (finger_sim.scene_changes.SceneChanges) and so
giving the same states as the task runner and `resim`. The state at
the crush keeps the force that broke it (its contact topics show it), the states after show the
scene without the object.

Each crush is a record (`Crush.to_values`, key → text, floats as repr so they read back exactly)
on the finger's `~/crush_log` topic (diagnostic_msgs/DiagnosticStatus, logged) and a warning in
the node's log; /diagnostics counts them. A reset restores the scene with every object.

Plain Python: no rclpy, no messages, no MCAP.
"""

from __future__ import annotations

from finger_sim.grasp_objects import Crush

#: What a finger with a breakable object reports beside its element outputs: its `~/crush_log` topic.
CRUSH_OUTPUT = "crush_log"
#: The `event` value of a crush record (as CommandEvent's `event` names what a command did).
CRUSH_EVENT = "crushed"


def crush_values(crush: Crush, episode: int) -> dict[str, str]:
    """The key-value record of `crush` in `episode` (floats as repr: exact when read back)."""
    return {"event": CRUSH_EVENT, "object": crush.object, "episode": str(episode), "step": str(crush.step),
            "t": repr(crush.t), "force": repr(crush.force), "break_force": repr(crush.break_force)}
