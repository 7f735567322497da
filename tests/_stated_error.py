"""Test helper: a coupled table whose checks never measured the bead density off its
reference, so that its separability error there is not stated (NaN) in one field."""

from __future__ import annotations

import numpy as np


def density_unmeasured(monkeypatch, field: str) -> None:
    """Make ``Table.separability_error`` NaN in ``field`` ("collision_frequency" or
    "se_median") wherever the bead density is off 2510 kg/m3."""
    from millfmu.stress_tables.table import Table

    real = Table.separability_error

    def unmeasured(self, point):
        out = real(self, point)
        if point.get("bead_density_kg_per_m3", 2510.0) != 2510.0:
            out[field] = out[field] * np.nan
        return out

    monkeypatch.setattr(Table, "separability_error", unmeasured)
