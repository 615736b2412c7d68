"""Controllers a task runs against: any Python callable named `module:callable`, and the shipped ones.

A controller *factory* is called once per run as `factory(sample_period, **params)` (sample
period in s, params from the command line) and returns the controller: a callable

    controller(t, setpoint, measured) -> command

called every `sample_steps` steps with the sample time t (s), the grip-force setpoint (N) and
the measured signals a real controller has (`MEASURED`, plus a drive's outputs when the scene
has one); it returns the scene input it commands (torque N·m, or a drive scene's voltage V: the task's
`controller.input`; a factory whose controllers command a voltage says so by `factory.input =
"voltage"`, and a suite runs it on the tasks of that input only).

Shipped factories: `grip_pi` (finger_sim.runtime.grip.GripController, the law of
finger_grip_controller: close, hold by PI, open), `grip_pi_aggressive` (the same law closing
fast with high gains: it overshoots, for comparison) and `grip_voltage` (a drive scene: PI on the
grip force commanding voltage, then 0 V once settled: the self-locking gear holds).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from finger_sim import drive_grip_law as drive_law
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError
from finger_sim.runtime.grip import GripController, GripSettings
from finger_sim.runtime.parameters import ParameterError

#: What every run measures for its controller: the force sensor and the MCP encoder.
MEASURED = (GRIP_FORCE.name, "theta1", "theta1_dot")
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
        return law.update(measured[GRIP_FORCE.name], sample_period)

    return control


def grip_pi_aggressive(sample_period: float, **params: float) -> Controller:
    """grip_pi with AGGRESSIVE settings (params override them)."""
    return grip_pi(sample_period, **{**AGGRESSIVE, **params})


#: grip_voltage defaults: closing voltage (V; ≈ 1.85 N at stall on the cup with the default drive),
#: PI gains on the grip-force error (V/N, V/(N·s)), voltage limit (V, the default drive's supply),
#: the band (fraction of the setpoint) and time (s) in it after which the voltage goes off, the
#: contact threshold (N) and the opening voltage (V) and time (s) on a setpoint of 0.
GRIP_VOLTAGE = {"closing_voltage": 2.0, "kp": 1.0, "ki": 20.0, "max_voltage": 6.0, "lock_band": 0.05,
                "lock_after": 0.05, "contact_threshold": 0.01, "opening_voltage": 2.0, "opening_time": 0.2}
#: grip_voltage's settings in the order `drive_grip_law.voltage_update` takes them.
VOLTAGE_LAW = ("closing_voltage", "kp", "ki", "max_voltage", "lock_band", "lock_after", "contact_threshold",
               "opening_voltage", "opening_time")


def grip_voltage(sample_period: float, feedback: str = GRIP_FORCE.name, force_per_unit: float = 1.0,
                 **params: float) -> Controller:
    """A grip controller for a self-locking drive, commanding the motor voltage (V): with a setpoint
    F* > 0 it applies `closing_voltage` until contact (F > contact_threshold), then
    u = closing_voltage + kp·e + ki·∫e dt on e = F* − F, |u| ≤ max_voltage; once |e| has
    stayed within lock_band·F* for lock_after s it switches the voltage off (0 V, for good until
    the setpoint changes): the self-locking gear holds the grip without power. A setpoint of 0
    opens: −opening_voltage for opening_time s, then 0 V. params: GRIP_VOLTAGE overrides.
    The force F it closes its loop on is force_per_unit × the measured signal `feedback`: grip_force
    (N, the ideal force sensor), or a scene sensor's reading (finger_sim.sensors) such as
    fsr_distal_measured (N) or motor_current_measured (A; force_per_unit then the grip per ampere, N/A)."""
    if not force_per_unit > 0.0 or not math.isfinite(force_per_unit):
        raise ConfigError("controller parameter force_per_unit", "a finite number > 0 (N per unit of feedback)",
                          force_per_unit)
    unknown = set(params) - set(GRIP_VOLTAGE)
    if unknown:
        raise ConfigError("controller parameter", f"one of {sorted(GRIP_VOLTAGE)}", sorted(unknown))
    p = {**GRIP_VOLTAGE, **params}
    state = {"setpoint": 0.0, "law": (0.0, 0.0, False, False, 0.0)}  # law: (integral, in_band, locked, touched, since)
    gains = tuple(p[name] for name in VOLTAGE_LAW)

    def control(t: float, setpoint: float, measured: Mapping[str, float]) -> float:
        if setpoint != state["setpoint"]:
            state["setpoint"], state["law"] = setpoint, drive_law.voltage_setpoint(t, state["law"][3])
        if feedback not in measured:
            raise ConfigError("controller parameter feedback", f"one of the measured signals {sorted(measured)}", feedback)
        integral, in_band, locked, touched, since = state["law"]
        integral, in_band, locked, touched, u = drive_law.voltage_update(
            integral, in_band, locked, touched, since, t, setpoint, force_per_unit * measured[feedback], sample_period,
            *gains)
        state["law"] = (integral, in_band, locked, touched, since)
        return u

    return control


grip_voltage.input = "voltage"  # type: ignore[attr-defined]


def commanded_input(factory: Factory) -> str:
    """The scene input a factory's controllers command: its `input` attribute, else "torque"."""
    return getattr(factory, "input", "torque")
