"""The run's terminal table (millfmu.runner.summary_table): rows evenly spaced in the
outputs, the last always shown."""

import pytest

from millfmu.runner import summary_table


def _times(n, rows=8):
    recs = [dict(t_s=60.0 * i, x10_m=1e-6, x50_m=2e-6, x90_m=4e-6, sf_per_s=1.0,
                 specific_energy_J_per_kg=0.0, holdup_kg=1.0) for i in range(n)]
    return [float(line.split()[0]) for line in summary_table(recs, rows).splitlines()[2:]]


@pytest.mark.parametrize("n, want", [
    (31, [0, 300, 600, 900, 1200, 1500, 1800]),  # the default scene: 1800 s, outputs every 60 s
    (8, [60.0 * i for i in range(8)]),
    (1, [0]),
    (100, [0, 900, 1800, 2700, 3600, 4500, 5400, 5940]),
])
def test_rows_are_evenly_spaced_and_end_with_the_last(n, want):
    assert _times(n) == want
