"""How the DEM's threads share out the chunks (millfmu.dem.engine.chunk_claims): every chunk
once, each thread's own region first, and the same results to the bit on any thread count."""

import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("numba")


def _claims_in_turn(nch, regions, own):
    """The chunks one thread gets when it claims alone until none is left."""
    import numba

    from millfmu.dem.engine.chunk_claims import claim, claim_counters, reset_claims

    @numba.njit
    def drain(claims, nch, own):
        reset_claims(claims, nch)
        out = np.full(nch + 1, -2, np.int64)
        for k in range(nch + 1):
            out[k] = claim(claims, nch, own)
            if out[k] < 0:
                return out[:k + 1]
        return out

    return list(drain(claim_counters(regions), nch, own))


@pytest.mark.parametrize("nch,regions", [(12, 2), (4, 3), (5, 1), (2, 4)])
def test_a_thread_takes_its_region_first_then_the_others_in_turn(nch, regions):
    bounds = [(r * nch) // regions for r in range(regions + 1)]
    for own in range(regions):
        got = _claims_in_turn(nch, regions, own)
        assert got[-1] == -1 and sorted(got[:-1]) == list(range(nch))
        order = [r % regions for r in range(own, own + regions)]
        assert got[:-1] == [c for r in order for c in range(bounds[r], bounds[r + 1])]


def test_the_counters_have_one_region_per_thread_on_a_line_each():
    from millfmu.dem.engine.chunk_claims import CLAIM_STRIDE, claim_counters

    assert CLAIM_STRIDE * 8 == 64
    assert claim_counters(3).shape == (3 * CLAIM_STRIDE,)
    assert claim_counters(0).shape == (CLAIM_STRIDE,)


SAME_ON_ANY_THREADS = r"""
import numpy as np
from millfmu.dem.mills.geometry import MillGeometry, place_beads
from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.engine.sim import DemSimulation
geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.004)
x = place_beads(geom, 17000, 0.4e-3, seed=7)
v = np.random.default_rng(8).normal(0.0, 0.5, size=x.shape)
out = []
for threads in (1, 2, 3):
    sim = DemSimulation(geom, BeadMaterial(), x, 0.4e-3, 500.0, 5e-6, velocities_m_per_s=v,
                        threads=threads)
    st = sim.run(60, record=True)
    out.append((sim.cb.size - 1, sim.x.copy(), sim.w.copy(), st.events.copy()))
print(out[0][0], len(out[0][3]), int(all(np.array_equal(o[1], out[0][1]) and
      np.array_equal(o[2], out[0][2]) and np.array_equal(o[3], out[0][3]) for o in out)))
"""


def test_a_run_is_the_same_to_the_bit_on_one_two_and_three_threads():
    """Four chunks of beads shared out by 1, 2 and 3 threads (regions of 4, 2 + 2 and
    1 + 1 + 2 chunks; with three threads on this machine's two cores some chunks are taken
    by a thread from another's region): positions, spins and recorded contacts equal."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    env["NUMBA_NUM_THREADS"] = "3"
    res = subprocess.run([sys.executable, "-c", SAME_ON_ANY_THREADS], capture_output=True,
                         text=True, env=env, check=True)
    nch, contacts, same = res.stdout.split()
    assert int(nch) == 4 and int(contacts) > 0
    assert same == "1"
