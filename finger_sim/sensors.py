"""Sensors as a controller sees them: measurement models applied to a run's outputs after the step.

A scene's optional `sensors:` mapping declares them; they read the run's true outputs and add a
`<name>_measured` column beside them, and never feed back into the dynamics:

    sensors:
      seed: 0                     # integer ≥ 0: the noise's seed (a run and its re-run are identical)
      motor_current: {noise: 0.002, resolution: 0.001, time_constant: 0.002, range: [-0.5, 0.5]}
      encoder: {resolution: 0.0052}        # reads motor_angle (rad at the motor)
      fsr_proximal: {range: [0.0, 10.0]}   # reads |contact force on the phalanx| (N)
      fsr_distal: {noise: 0.05}

Each sensor, in the order the signal goes through it (units of the signal it reads):
`time_constant` τ (s, 0 = none) a first-order lag y' = (x − y)/τ, exact for an input held over
each step at its value at the step's end (y_k = y_{k−1} + (1 − e^{−dt/τ})(x_k − y_{k−1}), y_0 = x_0:
a step at t = 0⁺ reads 1 − e^{−t/τ} at the samples); `noise` σ (0 = none) a Gaussian sample added
per reading; `range` [lo, hi] (none = unbounded) saturation; `resolution` q (0 = none) rounding
to the nearest multiple of q. `motor_current` and `encoder` need `model.drive`, the FSRs objects;
the FSRs' truth is added as `fsr_proximal` / `fsr_distal` (N), the others' is the drive's column.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_ANGLE, MOTOR_CURRENT
from finger_sim.effects.contact_outputs import CONTACT_FORCES
from finger_sim.errors import ConfigError
from finger_sim.scene_yaml import mapping, number, pair, whole

#: The sensors a scene may declare, and the true signal each reads (a run output's name, or for an
#: FSR the force components whose magnitude it reads).
SOURCES: dict[str, tuple[str, ...]] = {
    "motor_current": (MOTOR_CURRENT.name,),
    "encoder": (MOTOR_ANGLE.name,),
    **{f"fsr_{phalanx}": tuple(o.name for o in forces) for phalanx, forces in CONTACT_FORCES.items()},
}
#: Bounds of a sensor's values: far beyond a finger's signals (A, rad at the motor, N), finite.
MAX_SIGNAL = 1e6
MAX_TIME_CONSTANT = 1e3  # s
MAX_SEED = 2**63 - 1
_KEYS = {"noise", "resolution", "time_constant", "range"}


@dataclass(frozen=True)
class SensorModel:
    """One sensor's measurement model (units of the signal it reads; time constant in s)."""

    noise: float = 0.0
    resolution: float = 0.0
    time_constant: float = 0.0
    range: tuple[float, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"noise": self.noise, "resolution": self.resolution, "time_constant": self.time_constant}
        if self.range is not None:
            out["range"] = list(self.range)
        return out


@dataclass(frozen=True)
class SensorSet:
    """A scene's sensors ((name, model) pairs, in SOURCES' order: hashable) and the seed of their noise."""

    seed: int = 0
    pairs: tuple[tuple[str, SensorModel], ...] = ()

    @property
    def models(self) -> dict[str, SensorModel]:
        return dict(self.pairs)

    def to_dict(self) -> dict[str, Any]:
        return {"seed": self.seed, **{name: m.to_dict() for name, m in self.pairs}}


def sensors_from_dict(data: Any, *, has_drive: bool, has_objects: bool) -> SensorSet:
    """Validate a scene's `sensors:` mapping; ConfigError names the key, its range and the value."""
    data = mapping(data, "sensors", {"seed", *SOURCES})
    seed = whole(data.get("seed", 0), "sensors.seed", 0, MAX_SEED, f"an integer in [0, {MAX_SEED}]")
    models = {}
    for name in SOURCES:  # a fixed order: each sensor's noise stream does not depend on the file's order
        if name not in data:
            continue
        key = f"sensors.{name}"
        if name in ("motor_current", "encoder") and not has_drive:
            raise ConfigError(key, "a sensor of the drive's signals only with model.drive", name)
        if name.startswith("fsr_") and not has_objects:
            raise ConfigError(key, "a force-sensing resistor only with objects to touch", name)
        spec = mapping(data[name] if data[name] is not None else {}, key, _KEYS)
        lo_hi = None
        if "range" in spec:
            lo_hi = pair(spec["range"], f"{key}.range", MAX_SIGNAL)
            if not lo_hi[0] < lo_hi[1]:
                raise ConfigError(f"{key}.range", "[lo, hi] with lo < hi", list(lo_hi))
        models[name] = SensorModel(
            noise=number(spec.get("noise", 0.0), f"{key}.noise", minimum=0.0, maximum=MAX_SIGNAL),
            resolution=number(spec.get("resolution", 0.0), f"{key}.resolution", minimum=0.0, maximum=MAX_SIGNAL),
            time_constant=number(spec.get("time_constant", 0.0), f"{key}.time_constant", minimum=0.0,
                                 maximum=MAX_TIME_CONSTANT),
            range=lo_hi,
        )
    return SensorSet(seed=seed, pairs=tuple(models.items()))


class SensorBank:
    """The scene's sensors over one run: call `measure` on its output blocks in time order (the lag's
    state and the noise streams carry over, so blocks give the same readings as one call)."""

    def __init__(self, sensors: SensorSet, dt: float) -> None:
        self.sensors = sensors
        self.dt = dt
        # one stream per sensor, keyed by its place in SOURCES: adding a sensor leaves the others' noise alone
        names = list(SOURCES)
        self._rngs = {n: np.random.default_rng([sensors.seed, names.index(n)]) for n in sensors.models}
        self._lag: dict[str, float] = {}

    def column_names(self) -> tuple[str, ...]:
        """The columns `measure` returns: each FSR's truth, then every `<name>_measured`, in SOURCES' order."""
        truth = tuple(n for n in self.sensors.models if n.startswith("fsr_"))
        return (*truth, *(f"{n}_measured" for n in self.sensors.models))

    def measure(self, outputs: Mapping[str, np.ndarray], elapsed: float | None = None) -> dict[str, np.ndarray]:
        """The next block's columns (`column_names`) from the run's true outputs over that block, its
        samples dt apart; elapsed: the time from the previous reading to the block's first sample, s
        (default dt; the node reads at its publishing times, 0 for a repeated reading of a step)."""
        truths, readings = {}, {}
        for name, model in self.sensors.models.items():
            parts = [np.asarray(outputs[s], dtype=float) for s in SOURCES[name]]
            x = np.hypot(*parts) if len(parts) == 2 else parts[0]
            if name.startswith("fsr_"):
                truths[name] = x
            readings[f"{name}_measured"] = self._read(name, model, x, self.dt if elapsed is None else elapsed)
        return {**truths, **readings}

    def _read(self, name: str, model: SensorModel, x: np.ndarray, elapsed: float) -> np.ndarray:
        y = x.copy()
        if model.time_constant > 0.0:
            a = -math.expm1(-self.dt / model.time_constant)  # 1 − e^(−dt/τ), exact for small dt/τ
            first = -math.expm1(-elapsed / model.time_constant)  # over the gap before the block's first sample
            prev = self._lag.get(name, float(x[0]))  # the sensor starts settled on the first reading
            for k in range(len(x)):
                prev += (a if k else first if name in self._lag else 0.0) * (x[k] - prev)
                y[k] = prev
            self._lag[name] = prev
        if model.noise > 0.0:
            y = y + model.noise * self._rngs[name].standard_normal(len(y))
        if model.range is not None:
            y = np.clip(y, *model.range)
        if model.resolution > 0.0:
            y = np.round(y / model.resolution) * model.resolution
        return y
