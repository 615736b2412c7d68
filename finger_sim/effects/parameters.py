"""An effect's scene parameters, declared once: type, bounds, default, unit and meaning.

Each declaration is a pydantic v2 type (`annotation`: a float or a pair of floats with `Field`
bounds), from which `finger_sim.scene_schema` writes the JSON Schema that editors check scenes
with; the scene loader reads the value through `read`, which refuses it with today's one-line
`ConfigError` (key path, allowed range, value given: `finger_sim.scene_yaml.number` / `pair`), so the
editor and the loader apply the same bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import Field

from finger_sim.scene_yaml import number, pair


@dataclass(frozen=True)
class Parameter:
    """One scene key of an effect (under `model:`), SI units."""

    default: Any
    unit: str
    description: str
    minimum: float | None = None  # a scalar's bounds (inclusive)
    maximum: float | None = None
    bound: float | None = None  # a pair's bound on each component's magnitude

    @property
    def annotation(self) -> Any:
        """The pydantic type of the value, with its bounds, default and description."""
        doc = f"{self.description} ({self.unit})"
        if self.bound is None:
            return Annotated[float, Field(default=self.default, ge=self.minimum, le=self.maximum, description=doc,
                                          allow_inf_nan=False)]
        component = Annotated[float, Field(ge=-self.bound, le=self.bound, allow_inf_nan=False)]
        return Annotated[tuple[component, component], Field(default=self.default, description=doc)]

    def read(self, value: Any, key: str) -> Any:
        """The value of scene key `key` (its full path, e.g. model.damping), or ConfigError."""
        if self.bound is None:
            return number(value, key, minimum=self.minimum, maximum=self.maximum)
        return pair(value, key, self.bound)


def scalar(default: float, unit: str, description: str, *, minimum: float | None = None,
           maximum: float | None = None) -> Parameter:
    """A float in [minimum, maximum]."""
    return Parameter(default, unit, description, minimum=minimum, maximum=maximum)


def vector(default: tuple[float, float], unit: str, description: str, *, bound: float = math.inf) -> Parameter:
    """A pair of floats (x, y in the model plane), each of magnitude ≤ bound."""
    return Parameter(default, unit, description, bound=bound)


def bounded(description: str, *, minimum: float | None = None, maximum: float | None = None, strict: bool = False,
            default: Any = ..., nullable: bool = False) -> Any:
    """The pydantic type of a finite float in [minimum, maximum] ((minimum, maximum] if strict), as the
    loader's `scene_yaml.number` bounds it; `default` omitted: a required key. `nullable`: an explicit
    null is accepted too, for a key the loader reads as unset when null."""
    low = {"gt" if strict else "ge": minimum} if minimum is not None else {}
    if nullable:
        value = Annotated[float, Field(le=maximum, allow_inf_nan=False, **low)]
        return Annotated[value | None, Field(default=default, description=description)]
    return Annotated[float, Field(default=default, le=maximum, description=description, allow_inf_nan=False, **low)]


def pair_of(description: str, bound: float = math.inf, *, default: Any = ...) -> Any:
    """The pydantic type of a list of two finite floats, each of magnitude ≤ bound (`scene_yaml.pair`)."""
    limit = {} if math.isinf(bound) else {"ge": -bound, "le": bound}
    component = Annotated[float, Field(allow_inf_nan=False, **limit)]
    return Annotated[tuple[component, component], Field(default=default, description=description)]


def whole(description: str, minimum: int, maximum: int, *, default: Any = ...) -> Any:
    """The pydantic type of an integer in [minimum, maximum]; 3.0 counts as 3, in JSON Schema's "integer"
    and in the loader (`scene_yaml.whole`)."""
    return Annotated[int, Field(default=default, ge=minimum, le=maximum, description=description)]
