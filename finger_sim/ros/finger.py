"""One simulated finger of a stepping node: its simulator, held torque, topics and diagnostics window.

finger_node steps one Finger, finger_hand several in lock-step (finger_sim.ros.node's
SteppingNode runs the loop). A Finger is owned by the stepping thread once stepping has
begun, except `inbox`, which the executor thread fills.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from finger_sim import joints, kinematics
from finger_sim.actuators.drive_outputs import MESH_TORQUE
from finger_sim.grasp_objects import Crush
from finger_sim.kinematics import Vec3
from finger_sim.log.cdr_writer import JointStateCdr, MarkerArrayCdr, PoseStampedCdr
from finger_sim.ros import conversions, motor
from finger_sim.ros.interfaces import Endpoint
from finger_sim.run_log import CommandEvent
from finger_sim.runtime.commands import Inbox, TorqueCommands
from finger_sim.runtime.crushing import CRUSH_OUTPUT, crush_values
from finger_sim.runtime.diagnostics import DiagnosticsWindow, Level
from finger_sim.runtime.drive_commands import VoltageCommands
from finger_sim.runtime.hand_config import FingerSpec
from finger_sim.runtime.parameters import RunSettings, TorqueSource
from finger_sim.runtime.simulator import node_simulator
from finger_sim.runtime.timeline import Timeline
from finger_sim.scene import Scene, load_scene
from finger_sim.simulate import Simulator, State, output_names


class Finger:
    """The simulator of one finger and what the stepping loop keeps about it."""

    def __init__(self, spec: FingerSpec, settings: RunSettings, timeline: Timeline) -> None:
        self.spec = spec
        #: the simulator with the scene's changes (tip-force profile, crushing; finger_sim.scene_changes)
        self.changes = node_simulator(spec.scene_path, settings.physics_rate_hz)
        self.scene: Scene = self.changes.scene
        self.file_dt = load_scene(spec.scene_path).dt  # the scene file's own dt, for the record
        self.frames = conversions.FingerFrames.from_system(self.sim.system, spec.frame_prefix)
        self.reported = output_names(self.sim.system.elements, self.sim.q)  # e.g. grip_force: contact topics
        #: with a drive (spec §8) the command is a voltage and the motor's state is published (ros.motor)
        self.driven = self.scene.drive is not None
        if self.driven:
            self.reported = (*self.reported, *self.sim.system.output_names())
        #: the scene's motor current sensor (finger_sim.sensors), published beside the true current, or None
        self.current_sensor = (motor.CurrentSensor(self.scene, self.sim.dt) if motor.CurrentSensor.wanted(self.scene)
                               else None)
        if self.current_sensor is not None:
            self.reported = (*self.reported, "motor_current_measured")
        self.contact = conversions.ContactReport.of(self.frames, self.sim.system.elements)  # None: no contact
        self._contact_initial = self._contact_after = self.contact
        self.timeline = timeline
        self.crushed_now: list[Crush] = []  # the objects the last step crushed
        self._crush_records: list[Crush] = []  # crushes whose ~/crush_log record is not yet out
        if self.changes.watching:
            self.reported = (*self.reported, CRUSH_OUTPUT)
        self.mcp_joint = spec.frame_prefix + joints.JOINT_NAMES[0]
        scene_driven = settings.torque_source is TorqueSource.SCENE
        self.scene_steps = self.scene.step_count if scene_driven else None
        self.commands = (VoltageCommands(timeline, self.scene.drive, command_timeout=settings.command_timeout,
                                         accepting=not scene_driven) if self.scene.drive is not None else
                         TorqueCommands(timeline, max_torque=settings.max_torque,
                                        command_timeout=settings.command_timeout, accepting=not scene_driven))
        self.applied = self.initial_torque()  # N·m, over the last step
        self.max_residual = kinematics.constraint_norm(self.sim.system.params, self.sim.q)
        self.inbox = Inbox()
        self.lockstep_timeouts = 0  # states whose command did not come within lockstep_timeout
        self.diagnostics = DiagnosticsWindow(time.perf_counter())
        # the hot messages as CDR bytes, laid out once (finger_sim.log.cdr_writer)
        self._joints_cdr = JointStateCdr(self.frames.base_frame, self.frames.joint_names)
        self._pose_cdr = PoseStampedCdr(self.frames.base_frame)
        self._markers_cdr = MarkerArrayCdr(conversions.markers(self.frames, self.sim.q, 0))
        #: the positions, velocities and efforts of the last published joint states (`publish_state`)
        self.joint_values: tuple[Vec3, Vec3, Vec3] = ((0.0,) * 3,) * 3
        self.outputs: dict[str, Endpoint] = {}  # this finger's publishers by OUTPUTS key (`connect`)
        self.inputs: list[Endpoint] = []
        self.diag_name = self.event_name = self.crush_name = self.hardware_id = ""

    @property
    def sim(self) -> Simulator:
        """The simulator to step next (after a crush, that of the scene without the object)."""
        return self.changes.sim

    def connect(self, node_name: str, outputs: dict[str, Endpoint], inputs: list[Endpoint]) -> None:
        """Give the finger its publishers and subscriptions, and the names of its statuses; a
        missing table entry fails here, at start, never inside the stepping loop."""
        self.outputs, self.inputs = outputs, inputs
        self.joints_out, self.pose_out = outputs["joint_states"], outputs["fingertip_pose"]
        self.command_log_out, self.markers_out = outputs["command_log"], outputs.get("markers")
        self.crush_log_out = outputs.get("crush_log")  # a scene with a breakable object
        who = f"{node_name}: {self.spec.name + ' ' if self.spec.name else ''}"
        self.diag_name, self.event_name = who + "simulation", who + "command"
        self.crush_name = who + "crush"
        self.hardware_id = self.spec.frame_prefix + "finger"

    def has_controller(self) -> bool:
        """Lockstep: some node publishes on one of this finger's command topics."""
        return any(e.handle.get_publisher_count() > 0 for e in self.inputs)

    def outputs_matched(self, count_subscribers: Callable[[str], int]) -> bool:
        """Lockstep: each of this finger's publishers has matched every subscription the ROS graph
        (`count_subscribers(topic)`) knows on its topic. Discovery completes on each side apart: the
        node can see a controller's command publisher before its own publishers know the controller's
        subscriptions, and a volatile first state sent then is lost (the controller never answers it)."""
        return all(e.handle.get_subscription_count() >= count_subscribers(e.topic) for e in self.outputs.values())

    def initial_torque(self) -> float:
        """The torque shown at step 0 of an episode: the script's at t = 0, or none."""
        return self.scene.torque(0.0) if self.scene_steps is not None else 0.0

    def step(self, torque: float | None) -> State:
        """One physics step with `torque` (None: the scene's profile); SimulationDiverged passes."""
        state = self.changes.step(torque)
        self.crushed_now = self.changes.new()  # the node logs them; publish_state sends their records
        self._crush_records += self.crushed_now
        if self.changes.before is not None and self.contact is not None:
            # the crushing state reports with the objects the step ran with, the states after without the broken one
            self.contact, self._contact_after = (self._contact_after,
                                                 conversions.ContactReport(self.frames, self.sim.system.elements))
        self.applied = self.sim.torque
        residual = kinematics.constraint_norm(self.sim.system.params, state.q)
        if residual > self.max_residual:
            self.max_residual = residual
        return state

    def reset(self) -> CommandEvent:
        """Back to the scene's initial state; the 'reset' event."""
        self.changes.reset()
        self.crushed_now, self._crush_records = [], []
        self.contact = self._contact_after = self._contact_initial
        if self.current_sensor is not None:
            self.current_sensor.reset()
        self.inbox.clear()
        self.applied = self.initial_torque()
        return self.commands.reset("~/reset")

    def publish_state(self, publish: Callable[[Endpoint, Any], None], stamp: int, *, states: bool, markers: bool) -> None:
        """Publish this finger's joint states and fingertip pose (states) and markers, stamped `stamp` ns."""
        q = self.sim.q
        if self.crush_log_out is not None:  # whether or not the state is published: every crush is recorded
            for crush in self._crush_records:
                publish(self.crush_log_out, conversions.status(self.crush_name, self.hardware_id, bytes([Level.WARN]),
                                                               crush.log_line(), crush_values(crush, self.timeline.episode)))
            self._crush_records = []
        if states:  # CDR bytes: no message objects, no rclpy serialization
            effort = self.applied
            if self.driven:  # the mcp effort is the mesh torque on link 1; the motor's state has its own topics
                state = motor.motor_state(self.sim)
                effort = state[MESH_TORQUE.name]
                for key, msg in motor.messages(state):
                    publish(self.outputs[key], msg)
                if self.current_sensor is not None:
                    publish(self.outputs["motor/current_measured"], self.current_sensor.message(self.sim.step_index, state))
            self.joint_values = conversions.joint_values(self.frames, q, self.sim.v, effort)
            publish(self.joints_out, self._joints_cdr(stamp, *self.joint_values))
            publish(self.pose_out, self._pose_cdr(stamp, *conversions.fingertip_values(self.frames, q)))
            if self.contact is not None:  # a crushing state reports the force that broke the object
                contact = self.contact if self.changes.before is not None else self._contact_after
                for key, msg in contact.messages(*self.sim.state, stamp):
                    publish(self.outputs[key], msg)
        if markers and self.markers_out is not None:
            publish(self.markers_out, self._markers_cdr(stamp, conversions.marker_values(self.frames, q)))
