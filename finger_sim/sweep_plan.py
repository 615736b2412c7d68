"""A sweep's size and scenes without building the product: counts first, scenes block by block.

`finger-sim sweep` once validated and held a Scene for every combination before checking its
step budget: 10⁶ combinations took a minute and a gigabyte just to be refused. Here

- `check_values` validates each varied value once, alone in the base scene (Σ values scenes, not
  Π), so a bad value is refused up front, naming its key;
- `sweep_steps` counts the finger-steps of combinations [start, stop) by arithmetic over the
  mixed-radix digits of the combination index: only `duration` and `integrator.dt` change a
  run's step count, so the sum needs no scene at all;
- `scene_block` builds the scenes of one block of combinations, as the batch runs it;
- `Progress` reports runs done: a bar on a terminal, a line per quarter otherwise.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from finger_sim.errors import ConfigError
from finger_sim.scene import BREAK_EPS, Scene, scene_from_dict

#: The keys that set a run's step count (ceil(duration / dt)).
DURATION_KEY, DT_KEY = "duration", "integrator.dt"
#: Progress lines a non-terminal gets (at 25 %, 50 %, 75 %, 100 %).
PROGRESS_LINES = 4


def combination(varies: Sequence[Any], index: int) -> tuple[Any, ...]:
    """The values of combination `index` of the product (the last key varies fastest), in O(keys)."""
    values = []
    for v in reversed(varies):
        index, digit = divmod(index, len(v.values))
        values.append(v.values[digit])
    return tuple(reversed(values))


def _scene(base: Scene, varies: Sequence[Any], values: Sequence[Any]) -> Scene:
    from finger_sim.sweep import set_key

    data = base.to_dict()
    for v, value in zip(varies, values):
        set_key(data, v.key, value)
    try:
        return scene_from_dict(data)
    except ConfigError as exc:
        given = ", ".join(f"{v.key}={value!r}" for v, value in zip(varies, values))
        raise ConfigError(f"--vary ({given}): {exc.key}", exc.allowed, exc.got, problem=exc.problem) from None


def check_values(base: Scene, varies: Sequence[Any]) -> None:
    """Refuse (ConfigError naming the key and value) a varied value that no combination could take."""
    for v in varies:
        for value in v.values:
            _scene(base, [v], [value])


def scene_block(base: Scene, varies: Sequence[Any], start: int, stop: int) -> list[Scene]:
    """The validated scenes of combinations start..stop."""
    return [_scene(base, varies, combination(varies, i)) for i in range(start, stop)]


def _steps(duration: float, dt: float) -> int:
    return math.ceil(duration / dt - BREAK_EPS)


def sweep_steps(base: Scene, varies: Sequence[Any], start: int, stop: int) -> int:
    """Finger-steps of combinations [start, stop): Σ ceil(duration/dt), without building a scene.

    Values are taken as validated (`check_values`). Cost: O(keys × values of the timing keys²).
    """
    radices = [len(v.values) for v in varies]
    timing = {k: i for i, v in enumerate(varies) for k in (DURATION_KEY, DT_KEY) if v.key == k}
    if not timing:
        return (stop - start) * base.step_count
    return _steps_below(base, varies, radices, timing, stop) - _steps_below(base, varies, radices, timing, start)


def _steps_below(base: Scene, varies: Sequence[Any], radices: list[int], timing: dict[str, int], n: int) -> int:
    """Σ steps over combinations [0, n): for each position k, the combinations that share n's
    digits before k and have a smaller digit at k leave the positions after k free."""
    digits, rest = [], n
    for r in reversed(radices):
        rest, d = divmod(rest, r)
        digits.append(d)
    digits.reverse()
    if rest:  # n is the whole product: every combination
        return _free_sum(base, varies, radices, timing, -1, {})
    total = 0
    for k in range(len(radices)):
        fixed = {key: varies[i].values[digits[i]] for key, i in timing.items() if i < k}
        timing_here = [key for key, i in timing.items() if i == k]
        if timing_here:
            for d in range(digits[k]):
                total += _free_sum(base, varies, radices, timing, k, {**fixed, timing_here[0]: varies[k].values[d]})
        else:
            total += digits[k] * _free_sum(base, varies, radices, timing, k, fixed)
    return total


def _free_sum(base: Scene, varies: Sequence[Any], radices: list[int], timing: dict[str, int], k: int,
              fixed: dict[str, Any]) -> int:
    """Σ steps over every completion of the positions after k, the timing values in `fixed` held."""
    free_count = math.prod(r for i, r in enumerate(radices) if i > k and i not in timing.values())
    durations = [fixed[DURATION_KEY]] if DURATION_KEY in fixed else (
        list(varies[timing[DURATION_KEY]].values) if DURATION_KEY in timing else [base.duration])
    dts = [fixed[DT_KEY]] if DT_KEY in fixed else (
        list(varies[timing[DT_KEY]].values) if DT_KEY in timing else [base.dt])
    return free_count * sum(_steps(float(d), float(t)) for d in durations for t in dts)


class Progress:
    """Runs done out of `total`: a tqdm bar on a terminal, else a line at each quarter on `stream`."""

    def __init__(self, total: int, stream: TextIO | None = None) -> None:
        self.total, self.done, self._stream = total, 0, stream or sys.stderr
        self._bar = None
        self._next_line = 1
        if self._stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="run", desc="sweep", file=self._stream)

    def update(self, runs: int) -> None:
        self.done += runs
        if self._bar is not None:
            self._bar.update(runs)
            return
        while self.total and self._next_line <= PROGRESS_LINES and self.done * PROGRESS_LINES >= self._next_line * self.total:
            print(f"sweep: {self.done:,} of {self.total:,} runs ({100 * self._next_line // PROGRESS_LINES} %)",
                  file=self._stream, flush=True)
            self._next_line += 1

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
