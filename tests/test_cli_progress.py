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


def test_a_bar_into_a_log_file_is_redrawn_seldom(tmp_path):
    """Into a pipe or a file, tqdm redrew each bar every 0.1 s: a long run's batch log filled
    with megabytes of frames. Now every 10 s (PIPED_PROGRESS_INTERVAL_S), so three Phase I
    trajectories of about a second each draw only the first and last frames (and the close)."""
    import os
    import subprocess
    import sys

    env = {key: value for key, value in os.environ.items() if key != "TQDM_MININTERVAL"}
    command = [sys.executable, "-m", "dvrk_gym.cli.main", "collect", "--trajectories", "3", "--resolution", "320", "180"]
    done = subprocess.run([*command, "--out", str(tmp_path)], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    frames = [frame for frame in done.stderr.replace("\r", "\n").splitlines() if frame.startswith("Phase I trajectories")]
    assert frames[0].startswith("Phase I trajectories:   0%") and "3/3" in frames[-1]
    assert len(frames) <= 3, frames
