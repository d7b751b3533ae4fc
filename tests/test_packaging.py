"""The package as users get it: the wheel carries its data and its typing marker, the README and CI agree."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA_FILES = [
    "dvrk_gym/data/seita2018_phase1/X_train.npy",
    "dvrk_gym/data/seita2018_phase1/y_train.npy",
    "dvrk_gym/data/seita2018_phase1/LICENSE",
    "dvrk_gym/data/seita2018_phase1/README.md",
    "dvrk_gym/py.typed",  # PEP 561: type checkers read the package's own hints
]


@pytest.mark.slow
def test_built_wheel_contains_data_files_typing_marker_and_console_script(tmp_path):
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("dvrk_gym-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for data_file in DATA_FILES:
        assert data_file in names, f"{data_file} is missing from the wheel"
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert "dvrk-gym = dvrk_gym.cli.main:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_readme_test_command_is_the_one_ci_runs():
    ci_lines = (ROOT / ".ci" / "run").read_text().splitlines()
    command = next(line for line in ci_lines if "pytest" in line and not line.startswith("#"))
    assert command.strip() in (ROOT / "README.md").read_text()


def test_citation_file_names_the_paper_and_this_version():
    import re

    from dvrk_gym import __version__

    text = (ROOT / "CITATION.cff").read_text()
    assert f"version: {__version__}" in text
    assert "Two-Phase Calibration Procedure" in text and re.search(r"year: 2018", text)


def test_python_m_dvrk_gym_is_the_command():
    """``python -m dvrk_gym`` runs the ``dvrk-gym`` command (there was no ``__main__``)."""
    from dvrk_gym import __version__

    result = subprocess.run([sys.executable, "-m", "dvrk_gym", "--version"], capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode == 0, result.stderr
    assert __version__ in result.stdout
    refused = subprocess.run([sys.executable, "-m", "dvrk_gym", "nonsense"], capture_output=True, text=True, check=False, timeout=120)
    assert refused.returncode == 2 and "invalid choice: 'nonsense'" in refused.stderr
