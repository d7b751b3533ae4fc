"""The README is the front door: its code runs, its commands parse, its paths exist, its figures name their command.

The same holds for the deep dives it links to (``docs/*.md``): each is checked as the README
is, and every relative link of the README and the docs points at a file that exists (and at
a heading there, when it names one).

Every Python block runs as a script in a fresh interpreter, in a temporary folder, as a
reader who pastes it would run it; the import lines of the blocks above it in its section
come first (a reader reading the section top to bottom has them). Blocks that run the
paper's budgets (see :data:`SLOW_CALLS`) are marked slow. Every shell block is valid bash,
every command in it takes its arguments (``dvrk-gym`` and the benchmark scripts through
their parsers, in this process; the others with ``--help`` appended), and every figure (an image, or a table of measured numbers) names
the command that printed it.
"""

import ast
import importlib
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from benchmark_scripts import run_script

from dvrk_gym.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = {path.relative_to(ROOT).as_posix(): path.read_text() for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]}
"""The README and its deep dives, by path from the checkout's root. ``docs/reproduce/`` is a
run's output (``report.md``), checked against its own ``results.json`` by the reproduce tests."""
README = DOCUMENTS["README.md"]
CONTRIBUTING = (ROOT / "CONTRIBUTING.md").read_text()
COMMANDS = {"--version", "reproduce", "demo", "collect", "calibrate", "evaluate", "search", "debride", "baseline", "fidelity", "sweep"}
SLOW_CALLS = ("run_reproduce(", "run_calibration(", "run_paper_phase1(", "n_trajectories=57", ".learn(", "dvrk_gym_out/reproduce-quick")
"""A block with one of these runs the paper's budgets (or reads what they make), seconds to minutes: marked
``paper_budget``, which the default command leaves out and ``.ci/run`` runs after it."""
PREREQUISITES = {"dvrk_gym_out/reproduce-quick": ["reproduce", "--quick", "--no-progress"]}
"""A block that reads this folder gets the README's command that makes it run first (``dvrk-gym ...``)."""
COMMAND = re.compile(r"dvrk-gym\s+[a-z-]|python3?\s+(?:-m\s+[\w.]+|benchmarks/\w+\.py)|dask\s+\w+")
"""A command that prints figures: the package's CLI, a module or a benchmark script."""
MEASURED = re.compile(r"\d\.\d|\d/\d|\d%")
"""A table cell with a measured number: a decimal, a count out of a total, a percentage."""
FIGURE_WINDOW_LINES = 25
"""A figure's command must be within this many lines of it, in the same section."""


@dataclass(frozen=True)
class Block:
    """A fenced code block: its document, language, code, ``##`` section and first line (1-based)."""

    document: str
    language: str
    code: str
    section: str
    line: int

    @property
    def id(self) -> str:
        """The document (if not the README), the section's first words and the block's place among its section's blocks of its language."""
        same = [b for b in BLOCKS if (b.document, b.section, b.language) == (self.document, self.section, self.language)]
        prefix = "" if self.document == "README.md" else f"{Path(self.document).stem}-"
        return f"{prefix}{re.sub(r'[^a-z]+', '-', self.section.lower()).strip('-')[:24]}-{same.index(self) + 1}"


def _blocks(document: str) -> list[Block]:
    blocks, section, fence = [], "", None
    for number, line in enumerate(DOCUMENTS[document].splitlines(), start=1):
        if fence is None and line.startswith("```"):
            fence = (line[3:].strip(), number + 1, [])
        elif fence is not None and line.startswith("```"):
            blocks.append(Block(document, fence[0], "\n".join(fence[2]) + "\n", section, fence[1]))
            fence = None
        elif fence is not None:
            fence[2].append(line)
        elif line.startswith("## "):
            section = line[3:].strip()
    return blocks


BLOCKS = [block for document in DOCUMENTS for block in _blocks(document)]
PYTHON_BLOCKS = [b for b in BLOCKS if b.language == "python"]
SHELL_BLOCKS = [b for b in BLOCKS if b.language == "bash"]


def _code() -> list[str]:
    """The documents' code: each line of their fenced blocks, and each inline code span (joined across lines)."""
    prose = "\n".join(re.sub(r"```[a-z]*\n.*?```", "", text, flags=re.S) for text in DOCUMENTS.values())
    lines = [line for block in BLOCKS for line in block.code.splitlines()]
    return lines + [span.replace("\n", " ") for span in re.findall(r"`([^`]+)`", prose)]


def _commands(prefix: str) -> list[str]:
    """Every ``prefix ...`` the documents show, without comments or [optional] parts."""
    found = set()
    for code in _code():
        for match in re.finditer(rf"(?<![\w/-]){re.escape(prefix)} ([^#|]*)", code):
            text = re.sub(r"\[[^\]]*\]", "", match.group(1)).split("`")[0].strip()
            if text and "&&" not in text:
                found.add(text)
    return sorted(found)


def _shell_commands() -> list[str]:
    """Each command of the shell blocks (lines joined at backslashes, split at ``&&``), comments and [optional] parts removed."""
    commands = []
    for block in SHELL_BLOCKS:
        for line in block.code.replace("\\\n", " ").splitlines():
            line = re.sub(r"\[[^\]]*\]", "", line.split(" #", 1)[0])
            commands += [part.strip() for part in line.split("&&") if part.strip()]
    return commands


@pytest.mark.parametrize("command", _commands("dvrk-gym"))
def test_every_dvrk_gym_command_in_the_readme_parses(command):
    arguments = shlex.split(command)
    if arguments[0] not in COMMANDS:
        pytest.skip(f"prose, not a command: dvrk-gym {command}")
    try:
        build_parser().parse_args(arguments)
    except SystemExit as error:  # --version and --help exit 0
        assert error.code == 0, f"`dvrk-gym {command}` does not parse (exit {error.code})"


@pytest.mark.parametrize("command", [c for c in _commands("python") if c.startswith("benchmarks/")])
def test_every_benchmark_the_readme_names_exists_and_takes_its_arguments(command):
    script, *arguments = shlex.split(command)
    assert (ROOT / script).is_file(), f"the README or docs name {script}, which does not exist"
    result = run_script(ROOT / script, *arguments, parse_only=True)  # the script's parser takes them, then it stops
    assert result.returncode == 0, f"`python {command}`: {result.stderr[-1500:]}"


IMPORT_EVERY_SCRIPT = """
import importlib.util, pathlib, sys
folder = pathlib.Path("benchmarks").resolve()
sys.path[0] = str(folder)  # as `python benchmarks/NAME.py` puts the script's folder first
failed = []
for path in sorted(folder.glob("*.py")):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    try:
        spec.loader.exec_module(module)
    except Exception as error:
        failed.append(f"{path.name}: {type(error).__name__}: {error}")
print("\\n".join(failed))
"""


def test_every_benchmark_script_imports_in_a_fresh_python_with_only_its_own_folder_added():
    """What the in-process checks above cannot see: there, tests/ is on the import path too."""
    result = subprocess.run([sys.executable, "-c", IMPORT_EVERY_SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0 and not result.stdout.strip(), result.stdout + result.stderr[-1500:]


def test_every_benchmark_script_is_listed_and_every_listed_one_exists():
    scripts = sorted(path.name for path in (ROOT / "benchmarks").glob("*.py"))
    documents = "\n".join(DOCUMENTS.values())
    unlisted = [name for name in scripts if f"`{name}`" not in CONTRIBUTING and f"benchmarks/{name}" not in documents]
    assert not unlisted, f"benchmarks not in CONTRIBUTING's table of benchmarks nor in the README or docs: {unlisted}"
    listed = re.findall(r"^\| `(\w+\.py)` \|", CONTRIBUTING, flags=re.M)
    assert listed, "CONTRIBUTING.md has no table of benchmarks"
    assert not [name for name in listed if name not in scripts], f"CONTRIBUTING lists benchmarks that do not exist: {listed}"


@pytest.mark.parametrize("block", SHELL_BLOCKS, ids=lambda b: b.id)
def test_every_shell_block_of_the_readme_is_valid_bash(block):
    result = subprocess.run(["bash", "-n"], input=block.code, capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, f"{block.document} line {block.line}: {result.stderr}"


def _other_command_params() -> list:
    commands = dict.fromkeys(c for c in _shell_commands() if not c.startswith(("dvrk-gym ", "python benchmarks/", ". ")))
    return [pytest.param(c, id=c[:60], marks=[pytest.mark.slow] if "rl_zoo3" in c else []) for c in commands]  # RL Zoo's import: 30 s


@pytest.mark.parametrize("command", _other_command_params())
def test_every_other_command_of_the_readme_exists_and_takes_its_arguments(command):
    """pip, venv, pytest, RL Zoo, dask: the program exists and parses the arguments the README gives it."""
    program, *arguments = shlex.split(command)
    assert shutil.which(program), f"README runs {program!r}, which is not installed"
    if program in ("python", "python3"):
        program = sys.executable
    # --help last: the options before it are checked, then the help is printed; nothing is installed or run.
    result = subprocess.run([program, *arguments, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"`{command}`: {result.stderr[-1500:]}"


@pytest.mark.parametrize("name", sorted({name for text in DOCUMENTS.values() for name in re.findall(r"`(dvrk_gym(?:\.\w+)+)", text)}))
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


def _imports_above(block: Block) -> str:
    """The top-level import statements of the Python blocks above ``block`` in its section."""
    lines = []
    for above in PYTHON_BLOCKS[: PYTHON_BLOCKS.index(block)]:
        if above.section == block.section:
            tree = ast.parse(above.code)
            lines += [ast.get_source_segment(above.code, node) for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))]
    return "\n".join(line for line in lines if line) + "\n"


PAPER_BUDGET = [pytest.mark.slow, pytest.mark.paper_budget]


def _python_block_params() -> list:
    return [
        pytest.param(block, id=block.id, marks=PAPER_BUDGET if any(call in block.code for call in SLOW_CALLS) else [])
        for block in PYTHON_BLOCKS
    ]


def _run(arguments: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    environment = {**os.environ, "MPLBACKEND": "Agg", "SB3_LOGDIR": str(cwd / "sb3")}  # SB3 makes a log folder per model
    return subprocess.run(arguments, cwd=cwd, env=environment, capture_output=True, text=True, timeout=timeout)


CLAIMS = (
    (
        re.compile(r'^(\s*)info\["pixel_error"\].*#\s*(\d+) px, ([\d.]+) mm off'),
        'assert (round(info["pixel_error"]), round(info["mm_error"], 1)) == ({1}, {2}), (info["pixel_error"], info["mm_error"])',
    ),
    (
        re.compile(r'^(\s*)info\["outcome"\].*#\s*"(.)" here \(the jaws ([\d.]+) mm off\)'),
        'assert (info["outcome"], round(1e3 * float(np.hypot(*info["true_grip_offset_m"])), 1)) == ("{1}", {2}), info',
    ),
)
"""Results the README's example comments state (a GridTouch touch's error, a pick's outcome),
each checked by an assert put after its line when the block runs."""


def _with_claims_checked(code: str) -> tuple[str, int]:
    """``code`` with an assert after each line whose comment states a result, and how many."""
    lines, claims = [], 0
    for line in code.splitlines():
        lines.append(line)
        for pattern, check in CLAIMS:
            if match := pattern.match(line):
                lines.append(match[1] + check.format(*match.groups()))
                claims += 1
    return "\n".join(lines) + "\n", claims


@pytest.mark.parametrize("block", _python_block_params())
def test_every_python_block_of_the_readme_runs(block, tmp_path):
    for path, command in PREREQUISITES.items():
        if path in block.code:
            made = _run([sys.executable, "-m", "dvrk_gym.cli.main", *command], tmp_path, timeout=3600)
            assert made.returncode == 0, f"`dvrk-gym {' '.join(command)}`: {made.stderr[-1500:]}"
    script = tmp_path / "readme_block.py"
    code, _ = _with_claims_checked(block.code)  # an assert after each line whose comment states a result
    script.write_text("import numpy as np\n" + _imports_above(block) + code)
    result = _run([sys.executable, script.name], tmp_path, timeout=3600)
    assert result.returncode == 0, f"{block.document} line {block.line}:\n{result.stderr[-3000:]}"


def test_each_result_a_readme_comment_states_is_found_and_checked_when_its_block_runs():
    """The asserts run in :func:`test_every_python_block_of_the_readme_runs`; this checks that
    every stated result is found (a reworded comment would silently go unchecked)."""
    lines = [line for block in PYTHON_BLOCKS if block.document == "README.md" for line in block.code.splitlines()]
    found = [sum(bool(pattern.match(line)) for line in lines) for pattern, _ in CLAIMS]
    assert found == [2, 1], "each stated result is found (a comment reworded?)"
    checked, count = _with_claims_checked('x = 1\ninfo["outcome"]  # "C" here (the jaws 2.5 mm off)\n')
    assert count == 1 and checked.splitlines()[2].startswith('assert (info["outcome"]') and '("C", 2.5)' in checked


def _figures(document: str = "README.md") -> list[tuple[int, str]]:
    """(line, first line) of each image and each table with a measured number in its body, outside code blocks."""
    lines = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), DOCUMENTS[document], flags=re.S).splitlines()
    figures, table_start = [], None
    for number, line in enumerate(lines, start=1):
        if line.startswith("|") and table_start is None:
            table_start = number
        if table_start is not None and not line.startswith("|"):
            body = lines[table_start + 1 : number - 1]  # after the header and its rule
            if any(MEASURED.search(row) for row in body):
                figures.append((table_start, lines[table_start - 1]))
            table_start = None
        if line.startswith("!["):
            figures.append((number, line))
    return figures


def _section_window(document: str, line: int) -> str:
    """The document's text within FIGURE_WINDOW_LINES of ``line`` (1-based), cut at the headings around it."""
    lines = DOCUMENTS[document].splitlines()
    start, end = max(line - 1 - FIGURE_WINDOW_LINES, 0), min(line + FIGURE_WINDOW_LINES, len(lines))
    for index in range(line - 2, start - 1, -1):
        if lines[index].startswith("#"):
            start = index
            break
    for index in range(line, end):
        if lines[index].startswith("#"):
            end = index
            break
    return "\n".join(lines[start:end])


def test_the_figure_finder_finds_images_and_tables_of_numbers_but_not_reference_tables():
    starts = {text for _, text in _figures()}
    assert any(text.startswith("![") for text in starts)
    assert any(text.startswith("| method |") for text in starts)
    assert not any("CalibrationExploration-v0" in text for text in starts), "the env reference table holds no measurement"


def _figure_params() -> list:
    return [
        pytest.param(document, line, text, id=f"{'' if document == 'README.md' else Path(document).stem + '-'}line{line}")
        for document in DOCUMENTS
        for line, text in _figures(document)
    ]


@pytest.mark.parametrize(("document", "line", "text"), _figure_params())
def test_every_figure_in_the_readme_names_the_command_that_printed_it(document, line, text):
    assert COMMAND.search(_section_window(document, line)), (
        f"{document} line {line} ({text[:60]}...) names no command near it that printed it"
    )


def _anchor(heading: str) -> str:
    """GitHub's anchor for a Markdown heading: lower case, punctuation but ``-`` and ``_`` dropped, spaces as ``-``."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    return {_anchor(heading) for heading in re.findall(r"^#+ (.+)$", prose, flags=re.M)}


def _link_params() -> list:
    links = []
    for document, text in DOCUMENTS.items():
        prose = re.sub(r"```.*?```", "", text, flags=re.S)
        for target in dict.fromkeys(re.findall(r"\]\(([^)\s]+)\)", prose)):
            if not re.match(r"[a-z]+:", target):  # http(s), mailto: not checked offline
                links.append(pytest.param(document, target, id=f"{document}->{target}"))
    return links


@pytest.mark.parametrize(("document", "target"), _link_params())
def test_every_relative_link_points_at_a_file_and_heading_that_exist(document, target):
    path, _, anchor = target.partition("#")
    linked = (ROOT / document).parent / path if path else ROOT / document
    assert linked.exists(), f"{document} links to {target}: {linked} does not exist"
    if anchor:
        assert linked.suffix == ".md", f"{document} links to a heading of {linked}, which is not Markdown"
        assert anchor in _anchors(linked.read_text()), f"{document} links to #{anchor}, which is no heading of {path or document}"


def test_the_link_checker_reads_github_anchors():
    assert _anchor("The DNN at yaw 90: 3.06 mm") == "the-dnn-at-yaw-90-306-mm"
    assert _anchor("Performance against panda-gym") == "performance-against-panda-gym"
    assert (
        _anchor("Fidelity: how close the simulated robot is to the real one") == "fidelity-how-close-the-simulated-robot-is-to-the-real-one"
    )
