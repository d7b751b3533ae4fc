"""Every long command takes --no-progress, and then draws no progress bar."""

import pytest

from dvrk_gym.cli.main import build_parser, main

LONG_COMMANDS = [
    ["reproduce"],
    ["collect"],
    ["calibrate"],
    ["evaluate"],
    ["search"],
    ["fidelity"],
    ["sweep"],
    ["debride"],
    ["baseline", "train"],
    ["baseline", "evaluate"],
]


@pytest.mark.parametrize("command", LONG_COMMANDS, ids=" ".join)
def test_long_commands_take_no_progress(command):
    parser = build_parser()
    extra = ["--model", "m.zip"] if command == ["baseline", "evaluate"] else []
    assert parser.parse_args([*command, *extra, "--no-progress"]).no_progress is True


def test_collect_with_no_progress_draws_no_bar(tmp_path, capsys):
    code = main(["collect", "--trajectories", "1", "--resolution", "320", "180", "--out", str(tmp_path), "--no-progress"])
    captured = capsys.readouterr()
    assert code == 0 and (tmp_path / "phase1.npz").exists()
    assert "it/s" not in captured.err and "Phase I trajectories" not in captured.err


def test_collect_without_the_flag_draws_its_bar(tmp_path, capsys):
    assert main(["collect", "--trajectories", "1", "--resolution", "320", "180", "--out", str(tmp_path)]) == 0
    assert "Phase I trajectories" in capsys.readouterr().err  # so the test above can fail


@pytest.fixture
def linear_search(monkeypatch):
    """``dvrk-gym search`` with only the linear models on 300 rows: its bar, in seconds."""
    from dvrk_gym.calibration import search

    real = search.run_search

    def linear_only(X, y, **kwargs):
        linear = [spec for spec in search.paper_models(quick=True) if spec.family == "Lin"]
        return real(X[:300], y[:300], models=linear, **kwargs)

    monkeypatch.setattr(search, "run_search", linear_only)


@pytest.mark.parametrize("flag", [True, False], ids=["no-progress", "progress"])
def test_search_draws_its_bar_unless_told_not_to(linear_search, tmp_path, capsys, flag):
    arguments = ["search", "--quick", "--out", str(tmp_path), *(["--no-progress"] if flag else [])]
    assert main(arguments) == 0
    assert ("model search" in capsys.readouterr().err) is not flag
