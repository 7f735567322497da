"""The truncated Taylor step (Dyssol's crusher unit) of the integrator study: its order,
mass conservation, and its stability limit against the exact step."""

import numpy as np
from scipy.linalg import expm

from millfmu.studies.pbm_integrators import _order, taylor_step


def _operator(n=6, rate=1.0):
    """A small breakage operator: rates rising with size, equal fragments into every finer
    class, columns summing to zero."""
    a = np.zeros((n, n))
    for j in range(1, n):
        s = rate * (j / (n - 1)) ** 2
        a[:j, j] = s / j
        a[j, j] = -s
    return a


def test_taylor_steps_converge_with_orders_one_and_two_and_conserve_mass():
    a, y0 = _operator(), np.r_[np.zeros(5), 1.0]
    exact = expm(3.0 * a) @ y0
    for order in (1, 2):
        hs, errs = [], []
        for n in (16, 32, 64, 128):
            y = y0.copy()
            for _ in range(n):
                y = taylor_step(a, y, 3.0 / n, order)
            assert abs(y.sum() - 1.0) < 1e-14  # columns sum to zero: mass conserved
            hs.append(3.0 / n)
            errs.append(np.abs(y - exact).max())
        assert abs(_order(hs, errs, 1e-16) - order) < 0.1, (order, errs)


def test_taylor_step_diverges_beyond_its_stability_limit_where_the_exponential_does_not():
    a, y0 = _operator(rate=1e6), np.r_[np.zeros(5), 1.0]
    y = y0.copy()
    for _ in range(20):
        y = taylor_step(a, y, 1e-3, 2)  # h S_max = 1000, far beyond 2
    assert not np.all(np.isfinite(y)) or np.abs(y).max() > 1e6
    e = expm(1e-3 * a)
    z = np.linalg.matrix_power(e, 20) @ y0
    assert z.min() > -1e-15 and abs(z.sum() - 1.0) < 1e-12


def test_bench_pbm_writes_its_figures_as_one_record(tmp_path):
    """`millfmu bench pbm --json FILE`: the printed figures as one JSON record whose command
    names the options that were not the defaults (timings not checked)."""
    import json

    from millfmu.cli import main

    rec = tmp_path / "pbm.json"
    assert main(["bench", "pbm", "--classes", "20", "--hours", "0.01", "--repeats", "1", "--tanks", "2",
                 "--json", str(rec), "--host", "a test"]) == 0
    d = json.loads(rec.read_text())
    assert d["command"] == "millfmu bench pbm --classes 20 --hours 0.01 --repeats 1 --tanks 2"
    assert d["host"] == "a test" and set(d["figures"]) == {
        "step_us_20_classes", "exact_step_us_20_classes", "bdf_restarted_over_ours_20_classes",
        "bdf_span_over_ours_20_classes", "tanks_2_default_step_us", "tanks_2_default_propagator_ms",
        "tanks_2_stiff_step_us", "tanks_2_stiff_propagator_ms"}
    assert all(v > 0 for v in d["figures"].values())
    assert not list(tmp_path.glob(".*"))  # written whole, no part file left
    assert main(["bench", "pbm", "--json", str(tmp_path)]) == 2  # a folder: refused before timing


def test_the_integrator_table_prints_no_nan_for_a_missing_tolerance_or_order():
    """Fixed-step methods have no tolerance and diverging ones no order: the table says so in
    words, not as 'nan'."""
    from millfmu.studies.pbm_integrators import integrator_study

    lines = []
    res = integrator_study(quick=True, repeats=1, out=lines.append)
    text = "\n".join(lines)
    rows = [ln for ln in lines if ln.startswith("  exact step ") or ln.startswith("  Taylor ")]
    assert rows and all(ln.split()[3] == "-" for ln in rows)  # the rtol column of fixed-step methods
    assert any("none (its error grows)" in ln for ln in lines if ln.startswith("  measured orders"))
    assert res["stiff"]["orders"]["Taylor 1"] != res["stiff"]["orders"]["Taylor 1"]  # nan kept in the record
    assert "measured orders: exact step 2." in text
