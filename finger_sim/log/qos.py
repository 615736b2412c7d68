"""A publisher's QoS as rosbag2 stores it in a channel's `offered_qos_profiles` metadata.

rosbag2 (Jazzy and later; bag metadata version 9) writes a YAML list with one entry per
publisher, each with the keys below in this order and policies as rmw's strings
(rosbag2_storage/src/rosbag2_storage/qos.cpp, `YAML::convert<Rosbag2QoS>::encode`; the text
is yaml-cpp's `YAML::Dump`). Its MCAP storage reads the key back with the version of the
file's 'rosbag2' metadata record, and with the current version (9 in Jazzy) when there is no
such record, as in these logs; `ros2 bag play` then offers the recorded reliability and
durability (transient-local topics stay latched; a best-effort /clock stays best effort).
Humble reads integers here instead, and replays these logs with its default QoS.

Durations of 0 (rclpy's "unspecified", what a default profile holds) are written as the
infinite duration DDS reports for them in the ROS graph, {sec: 9223372036, nsec: 854775807},
which is what `ros2 bag record` stores. "system_default" policies are written as what Fast
DDS and Cyclone DDS resolve them to: keep_last, reliable, volatile, automatic.
"""

from __future__ import annotations

from typing import Any

from .errors import LogArgumentError

OFFERED_QOS_PROFILES = "offered_qos_profiles"  # the channel metadata key
_INFINITE_NS = (1 << 63) - 1  # RMW_DURATION_INFINITE
_NS_PER_S = 1_000_000_000
_SYSTEM_DEFAULTS = {"history": "keep_last", "reliability": "reliable", "durability": "volatile",
                    "liveliness": "automatic"}
_POLICIES = {
    "history": ("keep_last", "keep_all"),
    "reliability": ("reliable", "best_effort", "best_available"),
    "durability": ("volatile", "transient_local", "best_available"),
    "liveliness": ("automatic", "manual_by_topic", "best_available"),
}


def offered_qos_profiles(*profiles: Any) -> str:
    """The `offered_qos_profiles` text for publishers with these QoS profiles.

    A profile is an rclpy QoSProfile (read attribute by attribute; rclpy is not imported).
    LogArgumentError names the attribute that is missing or not a known policy.
    """
    return "\n".join(_entry(profile) for profile in profiles)


def _entry(profile: Any) -> str:
    lines = [f"- history: {_policy(profile, 'history')}",
             f"  depth: {_int(profile, 'depth')}",
             f"  reliability: {_policy(profile, 'reliability')}",
             f"  durability: {_policy(profile, 'durability')}"]
    for name in ("deadline", "lifespan"):
        lines += _duration(profile, name)
    lines.append(f"  liveliness: {_policy(profile, 'liveliness')}")
    lines += _duration(profile, "liveliness_lease_duration")
    avoid = getattr(profile, "avoid_ros_namespace_conventions", None)
    if not isinstance(avoid, bool):
        raise LogArgumentError("qos.avoid_ros_namespace_conventions", "a bool", avoid)
    lines.append(f"  avoid_ros_namespace_conventions: {'true' if avoid else 'false'}")
    return "\n".join(lines)


def _policy(profile: Any, name: str) -> str:
    value = getattr(profile, name, None)
    text = str(getattr(value, "name", "")).lower()  # rclpy's policy enums: KEEP_LAST → keep_last
    text = _SYSTEM_DEFAULTS[name] if text == "system_default" else text
    if text not in _POLICIES[name]:
        raise LogArgumentError(f"qos.{name}", f"an rclpy {name} policy ({', '.join(_POLICIES[name])})", value)
    return text


def _int(profile: Any, name: str) -> int:
    value = getattr(profile, name, None)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise LogArgumentError(f"qos.{name}", "an int >= 0", value)
    return value


def _duration(profile: Any, name: str) -> list[str]:
    value = getattr(profile, name, None)
    ns = getattr(value, "nanoseconds", None)
    if not isinstance(ns, int) or ns < 0:
        raise LogArgumentError(f"qos.{name}", "an rclpy Duration >= 0", value)
    sec, nsec = divmod(ns or _INFINITE_NS, _NS_PER_S)
    return [f"  {name}:", f"    sec: {sec}", f"    nsec: {nsec}"]
