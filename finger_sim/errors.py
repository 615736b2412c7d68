"""The core's errors: one small hierarchy, messages built in the constructor."""

from __future__ import annotations

import reprlib
from typing import Any

#: Characters of a value shown in an error message: a refused value may be megabytes long.
MAX_SHOWN_CHARS = 300


class _ShortRepr(reprlib.Repr):
    """reprlib's bounded repr, mappings in their own order (as repr() shows them), not sorted."""

    def repr_dict(self, x: dict[Any, Any], level: int) -> str:
        if not x:
            return "{}"
        if level <= 0:
            return "{...}"
        items = [f"{self.repr1(k, level - 1)}: {self.repr1(v, level - 1)}" for k, v in list(x.items())[:self.maxdict]]
        return "{" + ", ".join(items) + (", ..." if len(x) > self.maxdict else "") + "}"


_SHORT = _ShortRepr()
_SHORT.maxstring = _SHORT.maxother = _SHORT.maxlong = MAX_SHOWN_CHARS
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = _SHORT.maxset = 8


def shown(value: Any) -> str:
    """repr() of `value` for a message, bounded before it is built (a string cut at its end;
    lists and mappings by reprlib, with '...'), so a huge value costs nothing to refuse."""
    if isinstance(value, str):
        return repr(value) if len(value) <= MAX_SHOWN_CHARS else repr(value[:MAX_SHOWN_CHARS]) + "…"
    text = _SHORT.repr(value)
    return text if len(text) <= MAX_SHOWN_CHARS else text[:MAX_SHOWN_CHARS] + "…"


class FingerSimError(Exception):
    """Base of every error finger_sim raises on purpose."""


class ConfigError(FingerSimError, ValueError):
    """A configuration value is invalid: names the key, what is allowed and what arrived."""

    def __init__(self, key: str, allowed: str, got: Any, *, problem: str = "") -> None:
        self.key, self.allowed, self.got, self.problem = key, allowed, got, problem
        super().__init__(f"{key}: " + (f"{problem}; " if problem else "") + f"expected {allowed}, got {shown(got)}")

    def within(self, prefix: str) -> ConfigError:
        """The same error with its key prefixed, e.g. by the scene file's name."""
        return ConfigError(f"{prefix}: {self.key}", self.allowed, self.got, problem=self.problem)


class StabilityError(FingerSimError):
    """A method cannot step a scene stably at the requested dt: names the method, the scene, dt,
    the fastest mode s (1/s) and what works (an implicit method, auto, or the largest stable dt)."""

    def __init__(self, method: str, scene: str, dt: float, mode: complex, safe_dt: float, context: str = "") -> None:
        self.method, self.scene, self.dt, self.mode, self.safe_dt, self.context = method, scene, dt, mode, safe_dt, context
        super().__init__(
            f"integrator.method: {method} is unstable for scene '{scene}' at dt = {dt:g} s "
            f"(fastest mode |s| = {abs(mode):.4g} 1/s, |s|·dt = {abs(mode) * dt:.3g}); "
            f"use an implicit method (radau) or auto, or dt ≤ {safe_dt:.3g} s" + (f" ({context})" if context else "")
        )

    def with_context(self, context: str) -> StabilityError:
        """The same error with a note on where dt came from (e.g. a node parameter)."""
        return StabilityError(self.method, self.scene, self.dt, self.mode, self.safe_dt, context)

    def __reduce__(self) -> tuple[type, tuple[str, str, float, complex, float, str]]:  # picklable across processes
        return (StabilityError, (self.method, self.scene, self.dt, self.mode, self.safe_dt, self.context))


class SimulationDiverged(FingerSimError):
    """The state became non-finite or left the constraint manifold beyond repair.

    reason: what happened; method, t (s), dt (s): where, when known; hint: what works instead.
    """

    def __init__(self, reason: str, *, method: str | None = None, t: float | None = None,
                 dt: float | None = None, hint: str = "") -> None:
        self.reason, self.method, self.t, self.dt, self.hint = reason, method, t, dt, hint
        super().__init__(
            (f"{method}: " if method else "") + reason
            + (f" at t = {t:.6f} s" if t is not None else "")
            + (f" (dt = {dt:.6g} s)" if dt is not None else "")
            + (f"; {hint}" if hint else "")
        )


class ResourceError(FingerSimError):
    """A run would take more steps or memory than allowed: states the step count, what it
    would take, the limit and how to go ahead on purpose."""

    def __init__(self, steps: int, memory_bytes: float, max_steps: int, remedy: str) -> None:
        self.steps, self.memory_bytes, self.max_steps, self.remedy = steps, memory_bytes, max_steps, remedy
        super().__init__(
            f"a run of {steps:,} steps would hold about {_bytes(memory_bytes)} in memory, over the limit of "
            f"{max_steps:,} steps; {remedy}"
        )


def _bytes(n: float) -> str:
    """A byte count for messages, in SI units: 1.23 GB."""
    units = ("B", "kB", "MB", "GB", "TB", "PB", "EB")
    i = 0
    while n >= 1000.0 and i < len(units) - 1:
        n, i = n / 1000.0, i + 1
    return f"{n:.3g} {units[i]}"
