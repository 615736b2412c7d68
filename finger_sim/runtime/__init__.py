"""The ROS-free parts of finger_node: the stepping session (run state, pause/step/reset, lockstep),
pacing, command handling, parameters, diagnostics, log paths and the log's assembly.

Each module is plain Python over numbers and strings, unit-tested without DDS; finger_sim.ros.node
wires them to rclpy. Nothing here imports rclpy, a message package or MCAP.
"""
