"""The `sensors:` section of a scene as pydantic models, with `finger_sim.sensors`' bounds. Which
sensors a scene may have (the drive's need `model.drive`, the FSRs objects) stays the loader's check."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, create_model

from finger_sim.effects.parameters import bounded, pair_of, whole
from finger_sim.sensors import MAX_SEED, MAX_SIGNAL, MAX_TIME_CONSTANT, SOURCES, SensorModel

_M = SensorModel()


class SensorSchema(BaseModel):
    """One sensor's measurement model, in the units of the signal it reads."""

    model_config = ConfigDict(extra="forbid", title="Sensor")
    noise: bounded("Gaussian noise σ (0: none)", minimum=0.0, maximum=MAX_SIGNAL, default=_M.noise)
    resolution: bounded("quantization step q (0: none)", minimum=0.0, maximum=MAX_SIGNAL, default=_M.resolution)
    time_constant: bounded("first-order lag τ (s, 0: none)", minimum=0.0, maximum=MAX_TIME_CONSTANT,
                           default=_M.time_constant)
    range: pair_of("saturation [lo, hi], lo < hi (default: unbounded)", MAX_SIGNAL, default=None)


def sensors_model() -> type[BaseModel]:
    """`sensors:` — the seed and each sensor of `finger_sim.sensors.SOURCES` (null: all defaults)."""
    fields: dict[str, Any] = {name: (SensorSchema | None, Field(None, description=f"reads {', '.join(src)}"))
                              for name, src in SOURCES.items()}
    return create_model("Sensors", __config__=ConfigDict(extra="forbid"),
                        seed=(whole("the noise's seed", 0, MAX_SEED, default=0), 0), **fields)
