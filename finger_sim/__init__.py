"""finger_sim: constrained dynamics of a four-bar prosthetic finger, and a ROS 2 node over it.

The core (model, kinematics, dynamics, integrators, scenes, simulate) imports nothing
from ROS or MCAP; `finger_sim.ros` and `finger_sim.log` are adapters over it.
"""

__version__ = "0.1.0"
