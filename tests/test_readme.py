"""The README is the front door: its commands parse, its paths exist, its first example runs."""

import importlib
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from dvrk_gym.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
CONTRIBUTING = (ROOT / "CONTRIBUTING.md").read_text()
COMMANDS = {"--version", "reproduce", "demo", "collect", "calibrate", "evaluate", "search", "debride", "baseline", "fidelity", "sweep"}


def _code() -> list[str]:
    """The README's code: each line of its fenced blocks, and each inline code span (joined across lines)."""
    blocks = re.findall(r"```[a-z]*\n(.*?)```", README, flags=re.S)
    prose = re.sub(r"```[a-z]*\n.*?```", "", README, flags=re.S)
    lines = [line for block in blocks for line in block.splitlines()]
    return lines + [span.replace("\n", " ") for span in re.findall(r"`([^`]+)`", prose)]


def _commands(prefix: str) -> list[str]:
    """Every ``prefix ...`` the README shows, without comments or [optional] parts."""
    found = set()
    for code in _code():
        for match in re.finditer(rf"(?<![\w/-]){re.escape(prefix)} ([^#|]*)", code):
            text = re.sub(r"\[[^\]]*\]", "", match.group(1)).split("`")[0].strip()
            if text and "&&" not in text:
                found.add(text)
    return sorted(found)


@pytest.mark.parametrize("command", _commands("dvrk-gym"))
def test_every_dvrk_gym_command_in_the_readme_parses(command):
    arguments = shlex.split(command)
    if arguments[0] not in {
        "--version",
        "reproduce",
        "demo",
        "collect",
        "calibrate",
        "evaluate",
        "search",
        "debride",
        "baseline",
        "fidelity",
        "sweep",
    }:
        pytest.skip(f"prose, not a command: dvrk-gym {command}")
    try:
        build_parser().parse_args(arguments)
    except SystemExit as error:  # --version and --help exit 0
        assert error.code == 0, f"`dvrk-gym {command}` does not parse (exit {error.code})"


@pytest.mark.parametrize("command", [c for c in _commands("python") if c.startswith("benchmarks/")])
def test_every_benchmark_the_readme_names_exists_and_takes_its_arguments(command):
    script, *arguments = shlex.split(command)
    assert (ROOT / script).is_file(), f"README names {script}, which does not exist"
    # --help last: argparse checks the options before it, then prints the help and exits 0.
    result = subprocess.run([sys.executable, script, *arguments, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-1500:]


def test_every_benchmark_script_is_listed_and_every_listed_one_exists():
    scripts = sorted(path.name for path in (ROOT / "benchmarks").glob("*.py"))
    unlisted = [name for name in scripts if f"`{name}`" not in CONTRIBUTING and f"benchmarks/{name}" not in README]
    assert not unlisted, f"benchmarks not in CONTRIBUTING's table of benchmarks nor in the README: {unlisted}"
    listed = re.findall(r"^\| `(\w+\.py)` \|", CONTRIBUTING, flags=re.M)
    assert listed, "CONTRIBUTING.md has no table of benchmarks"
    assert not [name for name in listed if name not in scripts], f"CONTRIBUTING lists benchmarks that do not exist: {listed}"


@pytest.mark.parametrize("name", sorted(set(re.findall(r"`(dvrk_gym(?:\.\w+)+)", README))))
def test_every_module_path_in_the_readme_resolves(name):
    parts = name.split(".")
    for split in range(len(parts), 0, -1):  # the longest importable module, then attributes
        try:
            target = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for attribute in parts[split:]:
            target = getattr(target, attribute)
        return
    pytest.fail(f"{name} does not resolve")


def test_the_first_example_of_using_the_environments_runs():
    section = README.split("## Using the environments", 1)[1]
    code = section.split("```python", 1)[1].split("```", 1)[0]
    code = code.replace("camera_resolution=(1920, 1080)", "camera_resolution=(640, 360)")
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True, capture_output=True, text=True, timeout=300)
