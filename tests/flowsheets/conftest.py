import pytest


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    """One folder of unit FMUs for all flowsheet tests (built once, reused by content hash)."""
    return tmp_path_factory.mktemp("flowsheet_fmus")
