"""The kernels' compiled code is cached in a folder keyed by every kernel file's bytes:
numba checks a cached function against its own file only, so a caller whose callee in
another file changed would otherwise run the callee's old code."""

import shutil

import pytest

numba = pytest.importorskip("numba")

from millfmu.dem.engine import _jit  # noqa: E402


def _copy_kernel_sources(dst):
    from pathlib import Path

    dem = Path(_jit.__file__).resolve().parent.parent
    for d in _jit.KERNEL_DIRS:
        (dst / d).mkdir(parents=True)
        for f in (dem / d).glob("*.py"):
            shutil.copy2(f, dst / d / f.name)
    return dst


def test_the_key_follows_the_bytes_of_every_kernel_file_not_their_times(tmp_path):
    import os

    dem = _copy_kernel_sources(tmp_path / "dem")
    k0 = _jit.sources_key(dem)
    assert k0 == _jit.sources_key()  # the copies are the package's files
    callee = dem / "fluid" / "vans_kernels.py"
    os.utime(callee, (1e9, 1e9))
    assert _jit.sources_key(dem) == k0
    callee.write_bytes(callee.read_bytes() + b"\n")
    k1 = _jit.sources_key(dem)
    assert k1 != k0
    (dem / "coupling" / "new_law.py").write_text("X = 1\n")
    assert _jit.sources_key(dem) not in (k0, k1)


def test_kernels_are_cached_in_the_keyed_folder_and_numba_config_is_left_alone():
    from millfmu.dem.fluid import step_kernels

    folder = _jit.kernel_cache_dir()
    assert folder.name == f"millfmu-kernels-{_jit.sources_key()}"
    # numba's cache object of a dispatcher (internal): where its index and code go
    path = step_kernels.predictor._cache._cache_path
    assert path.startswith(str(folder))
    # other numba code in the process keeps numba's own places
    assert not numba.config.CACHE_DIR or str(folder) not in numba.config.CACHE_DIR


def test_a_user_cache_dir_is_the_base(monkeypatch, tmp_path):
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))
    assert _jit.kernel_cache_dir().parent == tmp_path


def test_old_folders_are_pruned_and_the_current_one_kept(tmp_path):
    import os

    keep = tmp_path / "millfmu-kernels-new"
    old = tmp_path / "millfmu-kernels-old"
    recent = tmp_path / "millfmu-kernels-recent"
    other = tmp_path / "something-else"
    for d in (keep, old, recent, other):
        d.mkdir()
        (d / "f.nbi").write_bytes(b"x")
    t_old = 1e9  # 2001
    for p in (old / "f.nbi", old, other / "f.nbi", other, keep / "f.nbi", keep):
        os.utime(p, (t_old, t_old))
    _jit._prune(tmp_path, keep)
    assert keep.exists() and recent.exists() and other.exists()
    assert not old.exists()
