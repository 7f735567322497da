"""Checkpointed runs: a run stopped after a checkpoint and resumed gives the outputs of the
run that was not stopped, to the digit; what cannot be resumed is refused by name."""

import json

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem import run as R  # noqa: E402
from millfmu.cli import main  # noqa: E402
from millfmu.dem.scene import load_scene  # noqa: E402
from tests._run_stats import stats_without_wall_clock  # noqa: E402


def dem_main(argv):
    return main(["dem"] + argv)


class Stopped(Exception):
    """Stands for the process being killed right after a checkpoint was written."""


def _scene():
    # coupled liquid, contacts recorded, frames counted: every part of a run's state
    return load_scene("accelerator_slice").with_overrides(
        sector_deg=30.0, spin_up_s=1e-3, record_s=1.5e-3, sample_every_s=5e-4)


def test_a_stopped_run_resumes_to_the_same_outputs(tmp_path, monkeypatch):
    whole = tmp_path / "whole"
    R.run_scene(_scene(), whole, progress=False, threads=1, window_s=5e-4)
    parts = tmp_path / "parts"
    write = R._write_checkpoint
    calls = []

    def write_then_stop(path, state):
        write(path, state)
        calls.append(path)
        if len(calls) == 3:  # 3 of the 4 samples before the end (spin-up included)
            raise Stopped

    monkeypatch.setattr(R, "_write_checkpoint", write_then_stop)
    with pytest.raises(Stopped):
        R.run_scene(_scene(), parts, progress=False, threads=1, window_s=5e-4,
                    checkpoint_every_s=1e-9)
    assert (parts / R.CHECKPOINT).exists() and not (parts / "stats.json").exists()
    # the recorded contacts are on disk, the checkpoint names their chunks' rows only
    from millfmu.dem.contact_log import FILE, ContactLog

    loop = R.load_checkpoint(parts)["loop"]
    assert "events" not in loop and len(loop["contact_log"]["rows"]) >= 1
    log = ContactLog.resume(parts / FILE, loop["contact_log"]["n_cols"], loop["contact_log"])
    assert log.total_rows == sum(loop["contact_log"]["rows"]) > 0
    # rows the stopped run appended after its checkpoint: cut, and recorded again
    with open(parts / FILE, "ab") as fh:
        fh.write(np.full((5, log.n_cols), 7.0).tobytes())
    # the same stop as a checkpoint of earlier sources (layout 1: the contacts in it)
    import shutil

    layout1 = tmp_path / "layout1"
    shutil.copytree(parts, layout1)
    st1 = R.load_checkpoint(layout1)
    st1["loop"]["events"] = [np.array(c) for c in log]
    del st1["loop"]["contact_log"]
    st1["format"] = 1
    (layout1 / FILE).unlink()
    R._write_checkpoint(layout1 / R.CHECKPOINT, st1)
    # a new run into the folder would overwrite the stopped one: refused, nothing touched
    before = (parts / R.CHECKPOINT).read_bytes()
    with pytest.raises(R.DemRunError, match="holds the checkpoint of a stopped run"):
        R.run_scene(_scene(), parts, progress=False, threads=1)
    assert (parts / R.CHECKPOINT).read_bytes() == before
    monkeypatch.setattr(R, "_write_checkpoint", write)
    written = []

    def write_then_count(path, state):
        write(path, state)
        written.append(state["checkpoint_every_s"])

    # made by earlier sources that give the same results to the digit (SAME_DEM_AS): resumed
    import pickle

    from millfmu.dem.tables import cache

    state = pickle.loads(before)
    here = state["kernel_version"]
    state["kernel_version"] = "sha256:earlier"
    R._write_checkpoint(parts / R.CHECKPOINT, state)
    same = {"sha256:earlier": "sha256:shipped", here: "sha256:shipped"}
    monkeypatch.setattr(cache, "SAME_DEM_AS", same)
    # resumed from the command line, as a user would; it goes on writing checkpoints at
    # the interval the run was started with (none given here)
    monkeypatch.setattr(R, "_write_checkpoint", write_then_count)
    assert dem_main(["run", "--resume", str(parts), "--no-progress"]) == 0
    assert written and set(written) == {1e-9}
    assert not (parts / R.CHECKPOINT).exists()
    assert stats_without_wall_clock(parts) == stats_without_wall_clock(whole)
    for f in ("fluid_fields.npz", "bead_samples.npz"):
        a, b = np.load(whole / f), np.load(parts / f)
        for k in a.files:
            assert np.array_equal(a[k], b[k], equal_nan=True), (f, k)
    assert (whole / "windows.csv").read_text() == (parts / "windows.csv").read_text()
    assert not (parts / FILE).exists() and not (whole / FILE).exists()
    monkeypatch.setattr(R, "_write_checkpoint", write)
    R.resume_run(layout1, progress=False)
    assert stats_without_wall_clock(layout1) == stats_without_wall_clock(whole)
    assert not (layout1 / FILE).exists()


def test_contact_log_chunks_resume_and_refusals(tmp_path):
    from millfmu.dem.contact_log import ContactLog, ContactLogError

    rng = np.random.default_rng(1)
    chunks = [rng.random((n, 4)) for n in (3, 0, 5, 2)]
    log = ContactLog(tmp_path / "c.f8", 4)
    for c in chunks[:3]:
        log.append(c)
    st = log.state()
    log.append(chunks[3])
    assert len(log) == 4 and log.total_rows == 10
    for a, b in zip(log, chunks):
        assert np.array_equal(a, b) and type(a) is np.ndarray
    assert np.array_equal(log.chunks(1, 4), np.concatenate(chunks[1:]))
    assert log.chunks(0, 0).shape == (0, 4)
    with pytest.raises(ValueError, match=r"must be \(n, 4\)"):
        log.append(np.zeros((2, 3)))
    # resumed at the state a checkpoint named: the last chunk is cut from the file
    back = ContactLog.resume(tmp_path / "c.f8", 4, st)
    assert back.total_rows == 8 and (tmp_path / "c.f8").stat().st_size == 8 * 4 * 8
    assert np.array_equal(back.chunks(0, 3), np.concatenate(chunks[:3]))
    with pytest.raises(ContactLogError, match="has 4 columns|4 columns; this version records 5"):
        ContactLog.resume(tmp_path / "c.f8", 5, st)
    with open(tmp_path / "c.f8", "r+b") as fh:
        fh.truncate(10)
    with pytest.raises(ContactLogError, match=r"c.f8: 10 bytes; the checkpoint recorded 8 "):
        ContactLog.resume(tmp_path / "c.f8", 4, st)
    back.remove()
    with pytest.raises(ContactLogError, match="c.f8: missing"):
        ContactLog.resume(tmp_path / "c.f8", 4, st)
    # a fresh log over a stale file starts empty
    (tmp_path / "d.f8").write_bytes(b"x" * 64)
    assert ContactLog(tmp_path / "d.f8", 4).total_rows == 0
    assert (tmp_path / "d.f8").stat().st_size == 0


def test_what_cannot_be_resumed_is_refused_by_name(tmp_path, monkeypatch, capsys):
    assert dem_main(["run", "--resume", str(tmp_path)]) == 2
    assert "no checkpoint.pkl (a run writes one" in capsys.readouterr().err
    assert dem_main(["run", "accelerator_slice", "--resume", str(tmp_path),
                     "--filling", "0.7"]) == 2
    assert "not allowed with accelerator_slice --filling" in capsys.readouterr().err
    assert dem_main(["run", "--out", str(tmp_path)]) == 2
    assert "a scene and --out are required" in capsys.readouterr().err
    assert dem_main(["run", "accelerator_slice", "--out", str(tmp_path / "x"),
                     "--checkpoint-every", "0"]) == 2
    assert "checkpoint_every_s = 0.0: must be > 0 s" in capsys.readouterr().err
    # a checkpoint of other DEM sources, and a broken file
    R._write_checkpoint(tmp_path / R.CHECKPOINT, dict(format=R.CHECKPOINT_FORMAT,
                                                      kernel_version="sha256:other"))
    with pytest.raises(R.DemRunError, match="made by other DEM sources"):
        R.resume_run(tmp_path)
    from millfmu.dem.tables import cache

    # sources mapped to another version than this one's are other sources
    monkeypatch.setattr(cache, "SAME_DEM_AS", {"sha256:other": "sha256:older-release"})
    with pytest.raises(R.DemRunError, match="made by other DEM sources"):
        R.resume_run(tmp_path)
    R._write_checkpoint(tmp_path / R.CHECKPOINT, dict(format=9))
    with pytest.raises(R.DemRunError, match="checkpoint layout 9; this version reads layouts 1, 2"):
        R.resume_run(tmp_path)
    (tmp_path / R.CHECKPOINT).write_bytes(b"not a pickle")
    with pytest.raises(R.DemRunError, match="not a readable checkpoint"):
        R.resume_run(tmp_path)


def test_gpu_device_refusals_name_the_item(tmp_path, capsys, monkeypatch):
    """``dem run --device gpu``: no checkpoints on the GPU, not with --resume, and without
    a CUDA GPU a clear error instead of a traceback (nothing written)."""
    assert dem_main(["run", "disc_slice", "--out", str(tmp_path / "a"), "--device", "gpu",
                     "--checkpoint-every", "60"]) == 2
    assert "checkpoints are written for runs on the CPU only (device = 'gpu')" in \
        capsys.readouterr().err
    assert dem_main(["run", "--resume", str(tmp_path), "--device", "gpu"]) == 2
    assert "not allowed with --device" in capsys.readouterr().err
    with pytest.raises(R.DemRunError, match="device = 'tpu': allowed 'cpu' or 'gpu'"):
        R.run_scene(load_scene("disc_slice"), tmp_path / "b", device="tpu")
    # as on a machine without a CUDA GPU (also under numba's simulator, which reports one)
    from numba import cuda

    monkeypatch.setattr(cuda, "is_available", lambda: False)
    assert dem_main(["run", "disc_slice", "--out", str(tmp_path / "c"), "--device", "gpu",
                     "--sector-deg", "10", "--no-gravity", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "disc_slice: device='gpu': numba.cuda finds no CUDA GPU" in err
    assert not (tmp_path / "c").exists()
    # the DEM bench against its peers (python -m benchmarks.dem_peers) refuses the same way
    from benchmarks.dem_peers import main as bench_main

    for argv in (["--profile"], ["--coupled", "full"]):
        assert bench_main(["--device", "gpu"] + argv) == 2
        assert "--device gpu: numba.cuda finds no CUDA GPU" in capsys.readouterr().err
    assert bench_main(["--bed", "none"]) == 2
    assert "--bed none: nothing to run without --coupled" in capsys.readouterr().err
    assert bench_main(["--bed", "none", "--profile", "--coupled", "--device", "gpu"]) == 2
    assert "--profile --coupled: the DEM on the CPU (here --device gpu)" in \
        capsys.readouterr().err
    assert bench_main(["--bed", "none", "--profile", "--coupled", "full", "--coupled-start",
                       "running"]) == 2
    assert "--coupled-start running: the 10-degree sector on the CPU only" in \
        capsys.readouterr().err
    assert bench_main(["--coupled-start", "early"]) == 2
    assert "--coupled-start early: applies to the coupled row" in capsys.readouterr().err
    for argv in (["--coupled", "full"], ["--coupled", "--device", "gpu"]):
        assert bench_main(["--bed", "none", "--coupled-start", "running"] + argv) == 2
        assert "--coupled-start running: the 10-degree sector on the CPU only" in \
            capsys.readouterr().err


def test_theta_cells_override_and_its_refusals(capsys):
    sc = load_scene("disc_slice").with_overrides(n_theta=32)
    assert sc.coupling.n_theta == 32
    from millfmu.dem.scene import DemSceneError

    with pytest.raises(DemSceneError, match="n_theta = 0: must be a whole number >= 1"):
        load_scene("disc_slice").with_overrides(n_theta=0)
    with pytest.raises(DemSceneError, match="theta cells are the coupled liquid's"):
        load_scene("disc_slice").with_overrides(fluid_mode="prescribed", n_theta=4)
    assert dem_main(["run", "--resume", "x", "--theta-cells", "8"]) == 2
    assert "not allowed with --theta-cells" in capsys.readouterr().err


def test_progress_of_a_stopped_run(tmp_path, monkeypatch, capsys):
    """dem progress reads a stopped run's checkpoint: time simulated of the protocol's,
    its cost, the bed's angular velocity; a folder without one is refused by name."""
    write = R._write_checkpoint

    written = []

    def write_then_stop(path, state):
        write(path, state)
        written.append(1)
        if len(written) == 2:
            raise Stopped

    monkeypatch.setattr(R, "_write_checkpoint", write_then_stop)
    with pytest.raises(Stopped):
        R.run_scene(_scene(), tmp_path, progress=False, threads=1, checkpoint_every_s=1e-9)
    assert dem_main(["progress", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "accelerator_slice" in text and "h per simulated second" in text
    assert "between the last two checkpoints" in text
    assert dem_main(["progress", str(tmp_path), "--json"]) == 0
    p = json.loads(capsys.readouterr().out)
    sc = _scene()
    assert p["t_s"] == pytest.approx(2 * sc.sample_every_s)
    assert p["phase"] == ("spin-up" if p["t_s"] < sc.spin_up_s else "recording")
    # the pace between the two checkpoints, one sample apart
    (s0, w0, c0), (s1, w1, c1) = R.load_checkpoint(tmp_path)["loop"]["checkpoints"]
    assert (s1 - s0) * sc.dt_s == pytest.approx(sc.sample_every_s)
    assert p["recent_wall_per_simulated_s"] == pytest.approx((w1 - w0) / sc.sample_every_s)
    assert p["recent_wall_to_go_s"] == pytest.approx(
        p["recent_wall_per_simulated_s"] * (p["total_s"] - p["t_s"]))
    assert p["total_s"] == pytest.approx(sc.spin_up_s + sc.record_s)
    assert p["beads"] > 0 and p["wall_s"] > 0 and p["particle_steps_per_s"] > 0
    assert 0.0 < p["cpu_s"] and p["cpu_per_simulated_s"] == pytest.approx(p["cpu_s"] / p["t_s"])
    assert 0.0 < p["angular_velocity_over_stirrer"] < 1.5
    # the accelerator has no disc faces; a sector without gravity no circumferential figures
    assert "first_bead_layer_angular_velocity_ratio" not in p and "beads_per_bin" not in p
    assert dem_main(["progress", str(tmp_path / "none")]) == 2
    assert "no checkpoint.pkl" in capsys.readouterr().err


def test_circumferential_distribution_hand_case():
    """Gravity along -y, rotation about +z (counter-clockwise): the top is +y, azimuth
    counted from it towards -x; the rising side (stirrer moving up) is x > 0."""
    from millfmu.dem.analysis.circumferential import circumferential

    deg = np.radians
    # beads at azimuths (from +x, counter-clockwise): 3 at 100 (upper half, falling side),
    # 1 at 200 (lower, falling), 2 at 300 (lower, rising), 2 at 20 (upper, rising)
    ang = deg(np.array([100, 100, 100, 200, 300, 300, 20, 20], dtype=float))
    x = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(8)]) * 0.02
    c = circumferential(x, (0.0, -9.81, 0.0), 360.0)
    assert c["rising_over_falling_half"] == pytest.approx(4 / 4)
    assert c["upper_over_lower_half"] == pytest.approx(5 / 3)
    # from the top (90 deg) in the direction of rotation: 100 -> 10 deg (bin 0),
    # 200 -> 110 (bin 3), 300 -> 210 (bin 7), 20 -> 290 (bin 9)
    assert c["beads_per_bin"] == [3, 0, 0, 1, 0, 0, 0, 2, 0, 2, 0, 0]
    assert c["largest_over_smallest_bin"] == 3.0  # empty bins count as one
    # the centroid: towards the rising side (+x here) and upwards (+y)
    assert c["centroid_rising_m"] == [pytest.approx(x[:, 0].mean(), abs=1e-15)]
    assert c["centroid_up_m"] == [pytest.approx(x[:, 1].mean(), abs=1e-15)]
    from millfmu.dem.analysis.circumferential import summary_line

    line = summary_line(c)
    assert "rising / falling half 1.000, upper / lower 1.667" in line
    assert f"at most {np.hypot(x[:, 0].mean(), x[:, 1].mean()) * 1e3:.2f} mm" in line
    assert summary_line({}) == ""
    # gravity along -x: up is +x, the rising side (up turned by -90 degrees) is -y
    cg = circumferential(x, (-9.81, 0.0, 0.0), 360.0)
    assert cg["centroid_up_m"] == [pytest.approx(x[:, 0].mean(), abs=1e-15)]
    assert cg["centroid_rising_m"] == [pytest.approx(-x[:, 1].mean(), abs=1e-15)]
    assert circumferential(x, (0.0, 0.0, 0.0), 360.0) == {}
    assert circumferential(x, (0.0, -9.81, 0.0), 60.0) == {}
    # time mean over samples (a run's recording): the second sample moves the bead at 200
    # degrees to 300 (bin 7) and one at 100 to 20 (bin 9)
    ang2 = deg(np.array([100, 100, 20, 300, 300, 300, 20, 20], dtype=float))
    x2 = np.column_stack([np.cos(ang2), np.sin(ang2), np.zeros(8)]) * 0.02
    m = circumferential([x, x2], (0.0, -9.81, 0.0), 360.0)
    assert m["samples"] == 2
    assert m["beads_per_bin"] == [2.5, 0, 0, 0.5, 0, 0, 0, 2.5, 0, 2.5, 0, 0]
    assert m["per_bin_over_mean"][0] == pytest.approx(2.5 / (8 / 12))
    assert m["rising_over_falling_half"] == pytest.approx(10 / 6)
    assert m["upper_over_lower_half"] == pytest.approx(10 / 6)
    assert m == circumferential(np.stack([x, x2]), (0.0, -9.81, 0.0), 360.0)
    assert circumferential([], (0.0, -9.81, 0.0), 360.0) == {}


def test_full_slice_with_gravity_reports_the_time_mean_circumferential_distribution(tmp_path):
    """A full slice with gravity across the axis writes the circumferential distribution
    of its recording (flow.circumferential), the time mean over the recorded samples: every
    bead in some bin at every sample, and the figures those samples give."""
    from millfmu.dem.analysis.circumferential import circumferential

    sc = load_scene("annulus").with_overrides(gravity_m_per_s2=(0.0, -9.81, 0.0), spin_up_s=5e-5,
                                              record_s=1.5e-4, sample_every_s=5e-5)
    st = R.run_scene(sc, tmp_path, progress=False, threads=1)
    c = st.flow["circumferential"]
    assert c["samples"] == 3 and c["azimuth_bin_deg"] == 30.0
    assert sum(c["beads_per_bin"]) == pytest.approx(st.beads)
    assert np.mean(c["per_bin_over_mean"]) == pytest.approx(1.0)
    assert (tmp_path / "circumferential.png").stat().st_size > 0
    # the beads barely move in 1.5e-4 s: the mean is (nearly) the placement's distribution
    x0 = R.make_simulation(sc, 1)[0].x
    c0 = circumferential(x0, sc.gravity_m_per_s2, 360.0)
    assert c["rising_over_falling_half"] == pytest.approx(c0["rising_over_falling_half"],
                                                          rel=0.02)
    # a sector without gravity has none
    st2 = R.run_scene(load_scene("annulus").with_overrides(
        spin_up_s=5e-5, record_s=5e-5, sample_every_s=5e-5), tmp_path / "no_g",
        progress=False, threads=1)
    assert "circumferential" not in st2.flow
