"""Controllers a task runs against: any Python callable named `module:callable`, and the shipped ones.

A controller *factory* is called once per run as `factory(sample_period, **params)` (sample
period in s, params from the command line) and returns the controller: a callable

    controller(t, setpoint, measured) -> command

called every `sample_steps` steps with the sample time t (s), the grip-force setpoint (N) and
the measured signals a real controller has (`MEASURED`, plus a drive's outputs when the scene
has one); it returns the scene input it commands (torque N·m today, `controller.input`).

Shipped factories: `grip_pi` (finger_sim.runtime.grip.GripController, the law of
finger_grip_controller: close, hold by PI, open) and `grip_pi_aggressive` (the same law closing
fast with high gains: it overshoots, for comparison).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from finger_sim.errors import ConfigError
from finger_sim.runtime.grip import GripController, GripSettings
from finger_sim.runtime.parameters import ParameterError

#: What every run measures for its controller: the force sensor and the MCP encoder.
MEASURED = ("grip_force", "theta1", "theta1_dot")
#: Grip PI settings of `grip_pi_aggressive`: a 3× faster closing torque that hits the object at
#: speed, and 5× the gains (a lightly damped loop): a large impact and a ringing force.
AGGRESSIVE = {"closing_torque": 0.05, "kp": 0.025, "ki": 20.0}


class Controller(Protocol):
    def __call__(self, t: float, setpoint: float, measured: Mapping[str, float]) -> float: ...


Factory = Callable[..., Controller]


def load_factory(spec: str) -> Factory:
    """The factory named `module:callable` (a dotted attribute path after the colon is allowed)."""
    module_name, sep, attr = spec.partition(":")
    if not sep or not module_name or not attr:
        raise ConfigError("--controller", "module:callable, e.g. finger_sim.tasks.controllers:grip_pi", spec)
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError("--controller", "an importable module", f"{module_name} ({exc})") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ConfigError("--controller", f"a callable defined in {module_name}", spec)
        obj = getattr(obj, part)
    if not callable(obj):
        raise ConfigError("--controller", "a callable", spec)
    return obj  # type: ignore[no-any-return]


def grip_pi(sample_period: float, **params: float) -> Controller:
    """finger_grip_controller's law (GripController) at the task's sample period; params:
    GRIP_PARAMETERS overrides (kp, ki, max_torque, closing_torque, ...)."""
    try:
        settings = GripSettings.from_values({**params, "sample_period": sample_period})
    except ParameterError as exc:
        raise ConfigError("controller parameter", "values within GRIP_PARAMETERS' ranges", str(exc)) from None
    law = GripController(settings)

    def control(t: float, setpoint: float, measured: Mapping[str, float]) -> float:
        if setpoint != law.setpoint:
            law.set_setpoint(setpoint)
        return law.update(measured["grip_force"], sample_period)

    return control


def grip_pi_aggressive(sample_period: float, **params: float) -> Controller:
    """grip_pi with AGGRESSIVE settings (params override them)."""
    return grip_pi(sample_period, **{**AGGRESSIVE, **params})
