"""The README's test command and CI test the same (issue 27): the system packages some tests
need are installed by one script that both CI (.ci/run) and the tests' own setup
(tests/conftest.py) run, not by CI alone."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ci_and_the_tests_setup_install_the_same_system_packages():
    script = ROOT / ".ci" / "system-deps"
    text = script.read_text()
    assert "libtbb12" in text and "g++ cmake" in text
    ci = (ROOT / ".ci" / "run").read_text()
    assert ".ci/system-deps" in ci and "apt-get" not in ci  # CI installs nothing of its own
    conftest = (ROOT / "tests" / "conftest.py").read_text()
    assert '"system-deps"' in conftest and "def pytest_configure" in conftest
