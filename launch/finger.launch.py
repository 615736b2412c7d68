"""finger_node with its parameter file, and optionally robot_state_publisher for RViz's RobotModel and TF.

    ros2 launch finger_sim finger.launch.py [use_rsp:=true] [namespace:=index frame_prefix:=index_]
                                            [params_file:=my_params.yaml]

robot_state_publisher (Jazzy) needs the URDF as its `robot_description` parameter at start. The
launch generates it with `finger-sim urdf` from `description_scene` and `frame_prefix`, so its
link and joint names carry the same prefix as finger_node's joint_states (robot_state_publisher's
own `frame_prefix` parameter would prefix only the TF frames, not the joint names it matches).
With no prefix and the shipped geometry it is share/finger_sim/urdf/finger.urdf byte for byte.

Untested where ROS 2's `launch` is absent: test/cli/test_launch.py checks this file statically.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import Command, LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import ExecutableInPackage, FindPackageShare

PACKAGE = "finger_sim"


def generate_launch_description() -> LaunchDescription:
    share = FindPackageShare(PACKAGE)
    namespace = LaunchConfiguration("namespace")
    frame_prefix = LaunchConfiguration("frame_prefix")
    # `--prefix=` with an empty prefix is one argument: the command line is split like a shell's.
    robot_description = ParameterValue(
        Command([ExecutableInPackage(executable="finger-sim", package=PACKAGE), " urdf ",
                 LaunchConfiguration("description_scene"), " --prefix=", frame_prefix]),
        value_type=str)
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file", default_value=PathJoinSubstitution([share, "config", "finger_node.yaml"]),
            description="finger_node's ROS parameter file"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the finger's topics and services"),
        DeclareLaunchArgument(
            "frame_prefix", default_value="",
            description="prefix of the finger's frames and joint names (overrides the params file's frame_prefix)"),
        DeclareLaunchArgument(
            "use_rsp", default_value="false",
            description="also start robot_state_publisher (TF and robot_description for RViz)"),
        DeclareLaunchArgument(
            "description_scene", default_value=PathJoinSubstitution([share, "config", "finger_default.yaml"]),
            description="scene file whose model.geometry robot_state_publisher's URDF takes (give the node's "
                        "scene if it changes the geometry)"),
        DeclareLaunchArgument(
            "use_sim_time", default_value="true",
            description="robot_state_publisher on finger_node's /clock (its joint_states carry sim time)"),
        Node(
            package=PACKAGE, executable="finger_node", namespace=namespace, output="screen",
            parameters=[LaunchConfiguration("params_file"), {"frame_prefix": ParameterValue(frame_prefix, value_type=str)}]),
        Node(
            package="robot_state_publisher", executable="robot_state_publisher", namespace=namespace, output="screen",
            parameters=[{"robot_description": robot_description,
                         "use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)}],
            condition=IfCondition(LaunchConfiguration("use_rsp"))),
    ])
