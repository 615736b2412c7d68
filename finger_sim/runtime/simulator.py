"""The node's simulator from its parameters: the scene file, stepped at 1/physics_rate_hz."""

from __future__ import annotations

from pathlib import Path

from finger_sim.errors import ConfigError, StabilityError
from finger_sim.scene import load_scene
from finger_sim.scene_changes import SceneChanges


def node_simulator(path: Path, physics_rate_hz: float) -> SceneChanges:
    """The scene at `path` with dt = 1/physics_rate_hz, stepped with its changes (a tip-force profile,
    crushing: finger_sim.scene_changes); errors name the parameter."""
    try:
        scene = load_scene(path)
    except ConfigError as exc:
        raise ConfigError(f"parameter 'scene' ({path}): {exc.key}", exc.allowed, exc.got) from None
    try:
        scene = scene.with_overrides(dt=1.0 / physics_rate_hz)
    except ConfigError as exc:
        raise ConfigError("parameter 'physics_rate_hz'", f"a rate whose step 1/rate fits the scene ({exc})", physics_rate_hz) from None
    try:
        return SceneChanges(scene)
    except StabilityError as exc:
        raise exc.with_context(f"dt = 1/physics_rate_hz, physics_rate_hz = {physics_rate_hz:g}") from None
