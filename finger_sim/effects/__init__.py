"""Force elements, one module per effect, registered by their scene key (see `base`).

Importing this package registers every effect. The five below come first, in this order,
because the order the elements are summed in fixes the last bits of every run (old logs
re-simulate bit for bit); any other module in this folder registers after them, in name
order, so a new effect needs only its module: a builder decorated with `@effect(key, ..., PARAMETERS,
outputs=...)`, which the scene loader, the JSON Schema and every output table read, and for its compiled
form one `kernel_law(<its force function>, <the state it reads>)` line, which the kernel's force sum
dispatches over (`kernel.force_laws`; test_new_effect), after `python -m finger_sim.kernel.force_laws` has
rewritten the committed dispatch (a test asks). Node topics for its outputs are extra (docs/architecture.md).
"""

import importlib
import pkgutil

from finger_sim.effects.base import (EFFECTS, Effect, ForceElement, Output, Smooth, build_elements, declared_outputs,
                                     declared_parameters, effect)

#: The original effects, in their summation order.
_FIRST = ("spring", "damping", "gravity", "tip_force", "stops")

for _name in (*_FIRST, *sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name not in (*_FIRST, "base", "parameters", "contact_schema"))):
    importlib.import_module(f"{__name__}.{_name}")

__all__ = ["EFFECTS", "Effect", "ForceElement", "Output", "Smooth", "build_elements", "declared_outputs", "declared_parameters",
           "effect"]
