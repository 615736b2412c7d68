"""MCAP logging: a non-blocking rosbag2-compatible recorder and a ROS-free reader.

Depends on mcap and mcap_ros2 only; rclpy is imported lazily, and only when the recorder is
handed message objects instead of CDR bytes. Nothing from the rest of finger_sim is imported
here: what a finger_node run stores is finger_sim.run_log's business.
"""

from mcap.writer import CompressionType

from .definitions import DEFINITION_SEPARATOR, message_definition, type_name_of
from .errors import (
    CorruptLogError,
    LogArgumentError,
    LogDecodeError,
    LogError,
    LogFileError,
    LogNotFoundError,
    MessageDefinitionNotFoundError,
    MissingMetadataError,
    MissingTopicsError,
    NotMcapError,
    RecorderStateError,
    TruncatedLogError,
)
from .reader import LogMessage, LogReader, TopicInfo, read_log
from .recorder import DEFAULT_CHUNK_INTERVAL_S, McapRecorder

__all__ = [
    "DEFAULT_CHUNK_INTERVAL_S",
    "DEFINITION_SEPARATOR",
    "CompressionType",
    "CorruptLogError",
    "LogArgumentError",
    "LogDecodeError",
    "LogError",
    "LogFileError",
    "LogMessage",
    "LogNotFoundError",
    "LogReader",
    "McapRecorder",
    "MessageDefinitionNotFoundError",
    "MissingMetadataError",
    "MissingTopicsError",
    "NotMcapError",
    "RecorderStateError",
    "TopicInfo",
    "TruncatedLogError",
    "message_definition",
    "read_log",
    "type_name_of",
]
