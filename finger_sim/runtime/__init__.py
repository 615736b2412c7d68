"""The ROS-free parts of finger_node: pacing, command handling, parameters, diagnostics, log paths.

Each module is plain Python over numbers and strings, unit-tested without DDS; finger_sim.ros.node
wires them to rclpy. Nothing here imports rclpy, a message package or MCAP.
"""
