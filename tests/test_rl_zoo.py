"""RL Zoo trains and replays GridTouch-v0 with the hyperparameters the package ships (no user file)."""

import os
import subprocess
import sys

import pytest

pytest.importorskip("rl_zoo3")


def _zoo(command: str, *arguments: str, cwd) -> subprocess.CompletedProcess:
    """Run ``python -m rl_zoo3.COMMAND`` in ``cwd``; SB3's logger folder goes there too (its
    default is a new /tmp/SB3-<date> folder per run, which the suite would leave behind)."""
    env_args = ["--algo", "sac", "--env", "dvrk_gym/GridTouch-v0", "--gym-packages", "dvrk_gym", "-f", str(cwd / "logs")]
    environment = {**os.environ, "SB3_LOGDIR": str(cwd / "sb3_log")}
    return subprocess.run(
        [sys.executable, "-m", f"rl_zoo3.{command}", *env_args, *arguments],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=900,
        env=environment,
    )


@pytest.mark.slow
def test_rl_zoo_trains_and_replays_grid_touch_with_the_shipped_hyperparameters(tmp_path):
    trained = _zoo("train", "--conf-file", "dvrk_gym.baselines.zoo", "-n", "250", "--seed", "0", cwd=tmp_path)
    assert trained.returncode == 0, trained.stdout[-2000:] + trained.stderr[-2000:]
    assert "HerReplayBuffer" in trained.stdout  # the package's SAC + HER settings, not RL Zoo's defaults
    assert list((tmp_path / "logs" / "sac").glob("*/dvrk_gym-GridTouch-v0.zip"))
    replayed = _zoo("enjoy", "-n", "3", "--no-render", "--deterministic", cwd=tmp_path)
    assert replayed.returncode == 0, replayed.stdout[-2000:] + replayed.stderr[-2000:]
    assert "Success rate" in replayed.stdout  # RL Zoo read is_success from the env's info


def test_the_shipped_hyperparameters_are_the_package_agents():
    from dvrk_gym.baselines.agents import AGENTS
    from dvrk_gym.baselines.zoo import hyperparams

    grid = hyperparams["dvrk_gym/GridTouch-v0"]
    assert grid["learning_rate"] == AGENTS["sac_her"].hyperparameters["learning_rate"]
    assert grid["replay_buffer_class"] == "HerReplayBuffer"
    assert eval(grid["policy_kwargs"]) == AGENTS["sac_her"].hyperparameters["policy_kwargs"]  # noqa: S307
