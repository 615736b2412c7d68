"""`finger_hand`: several fingers stepped in lock-step in one process, on one /clock, into one log.

The fingers come from a hand file (finger_sim.runtime.hand_config; `hand` parameter, default
the installed `three_fingers`): each has its own command and state topics in its namespace
(/<name>/motor_torque, /<name>/joint_command, /<name>/joint_states, /<name>/fingertip_pose,
/<name>/command_log …), its frame prefix on its links, joints and frames, and a base pose in
`hand_base`. One stepping thread steps every finger, then publishes their states with one
/clock tick (finger_sim.ros.node's SteppingNode, the loop finger_node runs for one finger),
so the fingers never drift apart in sim time and /clock has one publisher. The run's other
parameters are finger_node's (without scene and frame_prefix); ~/pause, ~/step and ~/reset act
on the whole hand. robot_description is finger_sim.urdf.hand_urdf: every finger under
hand_base at its pose. /joint_states holds every finger's joints (prefixed names, fingers in the
hand file's order) in one message per published state, stamped as the fingers' own, so that
robot_state_publisher with robot_description publishes the whole hand's /tf. The log
(<record_dir>/<hand>_<UTC start>.mcap) holds every finger's topics, the merged /joint_states and
one metadata record per finger (`finger_sim/<name>`).

    finger_hand --ros-args -p hand:=three_fingers
"""

from __future__ import annotations

import sys
from typing import Any

from finger_sim.errors import ConfigError
from finger_sim.log.cdr_writer import JointStateCdr
from finger_sim.ros.node import SteppingNode, run
from finger_sim.runtime.hand_config import FingerSpec, load_hand, resolve_hand
from finger_sim.runtime.parameters import HAND_PARAMETERS, HandSettings
from finger_sim.urdf import HAND_BASE, hand_urdf

NODE_NAME = "finger_hand"


class FingerHand(SteppingNode):
    """The fingers of a hand file as one ROS 2 node."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, HAND_PARAMETERS, HandSettings, **kwargs)
        self._merged_out = self._outputs["hand_joint_states"]
        self._merged_cdr = JointStateCdr(HAND_BASE, [n for f in self.fingers for n in f.frames.joint_names])

    def _finger_specs(self) -> list[FingerSpec]:
        assert isinstance(self.settings, HandSettings)
        self.hand_path = resolve_hand(self.settings.hand)
        return load_hand(self.hand_path)

    def _description(self) -> str:
        radii = {f.scene.phalanx_radius for f in self.fingers}
        if len(radii) > 1:  # hand_urdf draws every finger's capsules alike
            raise ConfigError(f"parameter 'hand' ({self.hand_path}): model.phalanx_radius",
                              "the same radii in every finger's scene", sorted(radii))
        return hand_urdf([(f.spec.frame_prefix, f.scene.params, f.spec.pose, f.scene.mcp_limits, f.scene.drive)
                          for f in self.fingers],
                         radii=radii.pop(), mcp_effort=self.settings.max_torque)

    def _log_name(self) -> str:
        return self.hand_path.stem

    def _publish_run_state(self, stamp: int) -> None:
        """/joint_states: the fingers' joint states just published, merged in finger order."""
        values = [f.joint_values for f in self.fingers]
        position, velocity, effort = ([x for v in values for x in v[i]] for i in range(3))
        self._publish(self._merged_out, self._merged_cdr(stamp, position, velocity, effort))


def main(args: list[str] | None = None) -> int:
    return run(FingerHand, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
