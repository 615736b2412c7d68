"""The kernel's explicit Runge–Kutta steps, generated from one template of the stage loop.

The compiled steps differ only in the state's width (q, q' and an actuator's own slots: 6 for the
linkage, 7 for the inductive drive's current) and the stage function they call (`numerics.accelerations`,
`drive.inductive_rates`). Written as one function over a run-time width, numba pays for it (row views,
a stage function taking an array: +5–30 % per step, docs/architecture.md); so the template is expanded
per step into straight-line source, as the hand-written copies were. numba caches only functions
defined in a source file, so the expansion is committed beside this module (`rk_steps.py`, warmed by
the install step); `python -m finger_sim.kernel.rk_template` rewrites it, and a test holds it equal to
`module_source()`.

The generated functions are plain: the stage function and `project` are free names, bound to their
compiled forms where the step is compiled (`jit.compiled` in `numerics` and `drive`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: The committed expansion of the template.
COMMITTED = Path(__file__).with_name("rk_steps.py")
#: Positions then velocities of the linkage in the flat state: the first slots of every step's x.
LINKAGE = ("x0", "x1", "x2", "w0", "w1", "w2")


@dataclass(frozen=True)
class RkStep:
    """One step generated from the template.

    name: the function's name; width: floats in x (q, q', then the own slots); stage: the name of the
    stage function, (m, t, q, q', u, own slots...) → (q'', the own slots' rates); state: what x holds
    (for the docstring); reference: the Python step it computes."""

    name: str
    width: int
    stage: str
    state: str
    reference: str

    @property
    def variables(self) -> tuple[str, ...]:
        """The stage state's local names: x0…x2 (q), w0…w2 (q'), then x6… (the own slots)."""
        return (*LINKAGE, *(f"x{c}" for c in range(len(LINKAGE), self.width)))


#: The kernel's explicit Runge–Kutta steps.
STEPS = (
    RkStep("rk_step", 6, "accelerations", "(q, q')", "ExplicitRungeKutta.step"),
    RkStep("inductive_rk_step", 7, "inductive_rates", "(q, q', i)", "StatefulRungeKutta._substep"),
)

TEMPLATE = '''

def {name}(m, tab, t, x, h, taus, k):
    """One projected explicit RK step on x = {state} in place: `{reference}`. Status.

    tab: (s + 3) × s tableau (A, B, C rows, then each stage's node index; `layout.tableau_array`);
    taus: the input at each distinct node time t + c h; k: s × {width} work array of stage derivatives.
    Zero tableau entries are skipped, as in Python. `{stage}` and `project`: bound where it is compiled.
    """
    s = tab.shape[1]
    for i in range(s):
        {variables} = {slots}
        for j in range(i):
            a = tab[i, j]
            if a != 0.0:
                ha = h * a
{row_sum}
        k[i, 0], k[i, 1], k[i, 2] = w0, w1, w2
        tau = taus[int(tab[s + 2, i])]
        {rates} = {stage}(m, t + tab[s + 1, i] * h, x0, x1, x2, w0, w1, w2, tau{own})
    for j in range(s):
        b = tab[s, j]
        if b != 0.0:
            hb = h * b
            for c in range({width}):
                x[c] += hb * k[j, c]
    return project(m, x)
'''


def step_source(step: RkStep) -> str:
    """The source of one step: the template with its width and stage function."""
    names = step.variables
    return TEMPLATE.format(
        name=step.name, state=step.state, reference=step.reference, width=step.width, stage=step.stage,
        variables=", ".join(names), slots=", ".join(f"x[{c}]" for c in range(step.width)),
        row_sum="\n".join(f"                {v} += ha * k[j, {c}]" for c, v in enumerate(names)),
        rates=", ".join(f"k[i, {c}]" for c in range(3, step.width)),
        own="".join(f", {v}" for v in names[len(LINKAGE):]))


def module_source() -> str:
    """The source of the generated module (`rk_steps.py`)."""
    header = '''"""The kernel's explicit Runge–Kutta steps, one per state width and stage function.

Generated from one template by `python -m finger_sim.kernel.rk_template`: do not edit.
"""
'''
    return header + "".join(step_source(step) for step in STEPS)


if __name__ == "__main__":
    COMMITTED.write_text(module_source(), encoding="utf-8")
