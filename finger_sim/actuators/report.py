"""The drive's energy report as one line (spec §8's power balance, J)."""

from __future__ import annotations

from collections.abc import Mapping


def energy_line(report: Mapping[str, float]) -> str:
    """`drive energy: W = … J  copper … J  mesh … J  rotor Δ … J  linkage Δ … J  dissipated … J  balance …`,
    the balance relative to the electrical work."""
    work = report["electrical_work"]
    scale = max(abs(work), abs(report["copper_loss"]), 1e-300)
    return (f"drive energy: electrical work = {work:.6e} J  copper loss = {report['copper_loss']:.6e} J  "
            f"mesh loss = {report['mesh_loss']:.6e} J  rotor ΔE = {report['rotor_energy_change']:+.3e} J  "
            f"linkage ΔE = {report['linkage_energy_change']:+.6e} J  dissipated = {report['dissipated']:.3e} J  "
            f"impacts = {report['impact_loss']:.3e} J  "
            + (f"magnetic ΔE = {report['magnetic_energy_change']:+.3e} J  " if "magnetic_energy_change" in report else "")
            + f"balance = {report['residual'] / scale:+.1e} of the work")
