"""ROS 2 adapters over the core: the node, its controller, message conversions and log replay."""
