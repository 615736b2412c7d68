"""finger_sim: constrained dynamics of a four-bar prosthetic finger, and a ROS 2 node over it.

The core (model, kinematics, dynamics, integrators, scenes, simulate) imports nothing
from ROS or MCAP; `finger_sim.ros` and `finger_sim.log` are adapters over it.
"""

__version__ = "0.1.0"

# The one place the rooms are wired: the compiled kernel sits above the core and serves it through
# `finger_sim.stepper_slot`; importing it installs it there (it loads numba only when first used).
from finger_sim import kernel as _kernel  # noqa: E402, F401


def __getattr__(name: str):  # type: ignore[no-untyped-def]
    """`from finger_sim import rollout` (finger_sim.rollouts.rollout), imported on first use so
    that `import finger_sim` stays light."""
    if name == "rollout":
        from finger_sim.rollouts import rollout

        return rollout
    raise AttributeError(f"module 'finger_sim' has no attribute {name!r}")
