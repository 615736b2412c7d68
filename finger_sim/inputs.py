"""Scripted motor-torque profiles τ(t), N·m on link 1, t in s.

A profile is evaluated at each integrator stage time. Piecewise-constant profiles
(step, square) also name their switching times, so the simulator can end a sub-step
exactly there and integrate each smooth piece on its own: a switch inside a step
would otherwise cost a first-order error.

Each profile also describes itself as data for the compiled kernel (`kernel_code`,
`kernel_params()`, packed by `profile_array`: the one flat encoding [code, params...]), as the
force elements do. Each law is written once, as the plain functions below (`ramp_torque` ...
`square_switch`, and `torque_at` / `switches_inside` over the flat encoding): the profiles call
them, and the compiled kernel compiles them.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import MISSING, asdict, dataclass, fields
from typing import Any, ClassVar

import numpy as np

from finger_sim.errors import ConfigError
from finger_sim.scene_yaml import magnitude

TorqueFn = Callable[[float], float]

#: A constant torque is split nowhere: a break closer than this (relative to dt) to a
#: step's end is taken as lying on it. Also the slack of the step count ceil(T/dt − ε).
BREAK_EPS = 1e-9
#: Largest torque level a profile may name, N·m (a finger motor gives ~0.05; this only keeps
#: the arithmetic finite).
MAX_TORQUE = 1e3
#: Largest ramp slope, N·m/s.
MAX_SLOPE = 1e6

#: Codes of the compiled profiles (`Profile.kernel_code`; `finger_sim.kernel.numerics.torque_at`).
#: HELD: a value held over the step (the node's command), passed to the kernel beside the profile.
HELD = 0
CONSTANT = 1
RAMP = 2
SINE = 3
STEP = 4
SQUARE = 5
#: The codes whose profile is constant between switches: τ on a step is its value at the step's middle.
PIECEWISE_CONSTANT = (STEP, SQUARE)


@dataclass(frozen=True)
class Profile:
    """Base of the torque profiles: smooth unless a subclass says otherwise."""

    kind: ClassVar[str]
    #: The compiled form's code (see HELD ... SQUARE); None: no compiled form, τ stays in Python.
    kernel_code: ClassVar[int | None] = None

    def __call__(self, t: float) -> float:
        raise NotImplementedError

    def kernel_params(self) -> tuple[float, ...]:
        """The numbers the compiled form `kernel_code` reads, in its order (SI): the fields."""
        return tuple(float(getattr(self, f.name)) for f in fields(self))  # (not `asdict`: its deep copies cost ≈ 20 µs)

    def breakpoints(self, t0: float, t1: float) -> list[float]:
        """Switching times strictly inside (t0, t1), s."""
        return []

    def on_segment(self, a: float, b: float) -> TorqueFn:
        """τ on the closed segment [a, b], which holds no switch inside it."""
        return self

    def shortest_interval(self) -> float:
        """The shortest time a fixed step must resolve, s: between two switches, or half a
        period; inf for a profile with no such scale. A step longer than this would hold more
        than one switch (or sample a periodic input below its Nyquist rate)."""
        return math.inf

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.kind, **asdict(self)}


@dataclass(frozen=True)
class Constant(Profile):
    """τ = value."""

    kind: ClassVar[str] = "constant"
    kernel_code: ClassVar[int | None] = CONSTANT
    value: float

    def __call__(self, t: float) -> float:
        return self.value


@dataclass(frozen=True)
class Ramp(Profile):
    """τ = offset + slope·t (the paper's input (8): offset 0.001 N·m, slope 0.01 N·m/s)."""

    kind: ClassVar[str] = "ramp"
    kernel_code: ClassVar[int | None] = RAMP
    offset: float
    slope: float

    def __call__(self, t: float) -> float:
        return ramp_torque(self.offset, self.slope, t)


@dataclass(frozen=True)
class Sine(Profile):
    """τ = offset + amplitude·sin(2π·frequency·t)."""

    kind: ClassVar[str] = "sine"
    kernel_code: ClassVar[int | None] = SINE
    amplitude: float
    frequency: float
    offset: float = 0.0

    def __call__(self, t: float) -> float:
        return sine_torque(self.amplitude, self.frequency, self.offset, t)

    def shortest_interval(self) -> float:
        return 0.5 / self.frequency


#: Levels of piecewise-constant profiles whose function `held_level` keeps (a dropped one is made again:
#: the solution then restarts once more, with the same numbers as a restart at every step).
LEVELS_KEPT = 1024


@functools.lru_cache(maxsize=LEVELS_KEPT)
def held_level(value: float, negative: bool) -> Constant:
    """The one function of a held level τ = value (N·m), keyed with its sign (−0.0 is not 0.0): a `Constant`,
    whose `value` tells a method that τ is the same at every stage."""
    return Constant(value)


@dataclass(frozen=True)
class _PiecewiseConstant(Profile):
    """A profile that switches between constants at known times."""

    def on_segment(self, a: float, b: float) -> TorqueFn:
        """The segment's level as one function object per level (`held_level`): an error-controlled method,
        which restarts its solution for a new function, then continues it across the output steps of a
        segment and restarts only at a switch."""
        value = self(0.5 * (a + b))
        return held_level(value, math.copysign(1.0, value) < 0.0)


@dataclass(frozen=True)
class Step(_PiecewiseConstant):
    """τ = before for t < at, after from t = at on."""

    kind: ClassVar[str] = "step"
    kernel_code: ClassVar[int | None] = STEP
    before: float
    after: float
    at: float

    def __call__(self, t: float) -> float:
        return step_torque(self.before, self.after, self.at, t)

    def breakpoints(self, t0: float, t1: float) -> list[float]:
        return [self.at] if t0 < self.at < t1 else []


@dataclass(frozen=True)
class Square(_PiecewiseConstant):
    """τ = offset + amplitude over the first half of each period, offset − amplitude over the second."""

    kind: ClassVar[str] = "square"
    kernel_code: ClassVar[int | None] = SQUARE
    amplitude: float
    frequency: float
    offset: float = 0.0

    def __call__(self, t: float) -> float:
        return square_torque(self.amplitude, self.frequency, self.offset, t)

    def shortest_interval(self) -> float:
        return 0.5 / self.frequency

    def breakpoints(self, t0: float, t1: float) -> list[float]:
        out: list[float] = []
        while (at := square_switch(self.frequency, t0, len(out))) < t1:
            out.append(at)
        return out


# -- the laws, once: plain float functions (τ in N·m, t in s), compiled by the kernel as they are --------
def ramp_torque(offset: float, slope: float, t: float) -> float:
    """τ = offset + slope·t."""
    return offset + slope * t


def sine_torque(amplitude: float, frequency: float, offset: float, t: float) -> float:
    """τ = offset + amplitude·sin(2π·frequency·t), frequency in Hz."""
    return offset + amplitude * math.sin(2.0 * math.pi * frequency * t)


def step_torque(before: float, after: float, at: float, t: float) -> float:
    """τ = before for t < at, after from t = at on."""
    return before if t < at else after


def square_torque(amplitude: float, frequency: float, offset: float, t: float) -> float:
    """τ = offset ± amplitude: + over the first half of each period, − over the second."""
    phase = (t * frequency) % 1.0
    return offset + (amplitude if phase < 0.5 else -amplitude)


def square_switch(frequency: float, t0: float, n: int) -> float:
    """The switch n = 0, 1, … of a square wave after t0 (s): the (n + 1)-th multiple of the half period
    strictly beyond the half period that holds t0."""
    half = 0.5 / frequency
    return (math.floor(t0 / half) + 1 + n) * half


def torque_at(prof: Sequence[float], held: float, t: float) -> float:
    """τ(t) of a profile in its flat encoding [code, params...] (`profile_array`); HELD returns `held`."""
    code = int(prof[0])
    if code == RAMP:
        return ramp_torque(prof[1], prof[2], t)
    if code == SINE:
        return sine_torque(prof[1], prof[2], prof[3], t)
    if code == STEP:
        return step_torque(prof[1], prof[2], prof[3], t)
    if code == SQUARE:
        return square_torque(prof[1], prof[2], prof[3], t)
    if code == CONSTANT:
        return prof[1]
    return held


def switches_inside(prof: Sequence[float], t0: float, t1: float, eps: float) -> bool:
    """Whether a switch of a profile in its flat encoding lies in (t0 + eps, t1 − eps): the test the
    Simulator makes on `Profile.breakpoints(t0, t1)` before it splits a step (eps in s)."""
    code = int(prof[0])
    if code == STEP:
        at = prof[3]
        return t0 < at < t1 and t0 + eps < at < t1 - eps
    if code == SQUARE:
        n = 0
        at = square_switch(prof[2], t0, n)
        while at < t1:
            if t0 + eps < at < t1 - eps:
                return True
            n += 1
            at = square_switch(prof[2], t0, n)
    return False


def profile_array(profile: Profile) -> np.ndarray | None:
    """[kernel_code, *kernel_params()] as float64 for the compiled kernel; None without a compiled form."""
    if profile.kernel_code is None:
        return None
    return np.array([float(profile.kernel_code), *profile.kernel_params()], dtype=np.float64)


#: The compiled form of a held value (the value itself is passed beside it).
HELD_ARRAY = np.array([float(HELD)])


PROFILES: dict[str, type[Profile]] = {cls.kind: cls for cls in (Constant, Ramp, Step, Square, Sine)}


#: Bound on each field of a profile (by name), in its unit: N·m, N·m/s, s.
_LIMITS = {"slope": MAX_SLOPE, "at": math.inf, "frequency": math.inf}


def profile_from_dict(data: Any, key: str = "input.torque") -> Profile:
    """A profile from its scene mapping, e.g. {type: ramp, offset: 0.001, slope: 0.01}."""
    if not isinstance(data, dict):
        raise ConfigError(key, f"a mapping with 'type' in {sorted(PROFILES)}", data)
    kind = data.get("type")
    if not isinstance(kind, str) or kind not in PROFILES:
        raise ConfigError(f"{key}.type", f"one of {sorted(PROFILES)}", kind)
    cls = PROFILES[kind]
    fields_ = {f.name: f for f in fields(cls) if f.name != "kind"}  # ClassVars excluded
    names = list(fields_)
    required = [f for f in names if fields_[f].default is MISSING]
    unknown = sorted((k for k in data if k not in names and k != "type"), key=str)
    if unknown:
        raise ConfigError(key, f"only keys {names} (and 'type') for type {kind}", unknown[0], problem="unknown key")
    values = {}
    for name in names:
        if name not in data:
            if name in required:
                raise ConfigError(f"{key}.{name}", f"a number (required for type {kind})", None)
            continue
        values[name] = magnitude(data[name], f"{key}.{name}", _LIMITS.get(name, MAX_TORQUE))
    if "frequency" in values and not values["frequency"] > 0:
        raise ConfigError(f"{key}.frequency", "a number > 0 (Hz)", data["frequency"])
    return cls(**values)


def steps_on_segment(profile: Any, k: int, dt: float, n: int) -> int:
    """How many of the n steps from index k lie on the profile's current segment with room to spare:
    every step ends before the next switch (less `BREAK_EPS`·dt), so each is held at the first one's
    value, as `Simulator.step` holds it (`on_segment`). n for a profile without switches."""
    if not isinstance(profile, Profile) or profile.kernel_code not in PIECEWISE_CONSTANT:
        return n
    t0 = k * dt
    switches = [b for b in profile.breakpoints(t0, (k + n) * dt) if b > t0]
    if not switches:
        return n
    limit = min(switches) - BREAK_EPS * dt  # the steps k … k + count − 1 end before it: (k + count)·dt < limit
    count = max(0, min(n, int((limit - t0) / dt)))  # a first guess, made exact on the grid's own times
    while count > 0 and (k + count) * dt >= limit:
        count -= 1
    while count < n and (k + count + 1) * dt < limit:
        count += 1
    return count
