"""The core's errors: one small hierarchy, messages built in the constructor."""

from __future__ import annotations

from typing import Any


class FingerSimError(Exception):
    """Base of every error finger_sim raises on purpose."""


class ConfigError(FingerSimError, ValueError):
    """A configuration value is invalid: names the key, what is allowed and what arrived."""

    def __init__(self, key: str, allowed: str, got: Any) -> None:
        self.key, self.allowed, self.got = key, allowed, got
        super().__init__(f"{key}: expected {allowed}, got {got!r}")


class StabilityError(FingerSimError):
    """A method cannot step a scene stably at the requested dt."""


class SimulationDiverged(FingerSimError):
    """The state became non-finite or left the constraint manifold beyond repair."""
