"""``dvrk-gym baseline train`` killed with SIGKILL mid-training: the same command resumes from
the saved state and writes the model a training never stopped writes, weight for weight."""

import json
import signal
import subprocess
import time
import zipfile

import pytest
import torch
from faults import ROOT, cli_command, environment, run_cli

from dvrk_gym.baselines import load_agent

pytestmark = pytest.mark.slow

TRAIN = (
    "baseline",
    "train",
    "--steps",
    "100",
    "--learning-starts",
    "10",
    "--eval-points",
    "3",
    "--resolution",
    "320",
    "180",
    "--no-progress",
)


def _saved_steps(path) -> int:
    """Env steps of the training state at ``path``; 0 while there is none (it is written atomically)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return json.loads(archive.read("state.json"))["num_timesteps"]
    except FileNotFoundError:
        return 0


def _curve(folder):
    return json.loads((folder / "learning_curve.json").read_text())["points"]


def test_a_killed_training_resumes_to_the_model_of_one_never_stopped(tmp_path):
    never_stopped = run_cli(*TRAIN, "--out", str(tmp_path / "whole"))
    assert never_stopped.returncode == 0, never_stopped.stderr
    assert not (tmp_path / "whole" / "training_state.zip").exists()

    out = tmp_path / "killed"
    state = out / "training_state.zip"
    with open(tmp_path / "first.log", "w") as log:
        first = subprocess.Popen(
            cli_command(*TRAIN, "--save-every", "20", "--out", str(out)), stdout=log, stderr=subprocess.STDOUT, env=environment(), cwd=ROOT
        )
        deadline = time.monotonic() + 240
        while _saved_steps(state) < 40 and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        first.send_signal(signal.SIGKILL)
        first.wait()
    saved = _saved_steps(state)
    assert 40 <= saved < 100, (tmp_path / "first.log").read_text()
    assert not (out / "model.zip").exists()

    again = run_cli(*TRAIN, "--save-every", "20", "--out", str(out))
    assert again.returncode == 0, again.stderr
    assert f"resumed the training saved in {state}" in again.stdout
    assert not state.exists()
    whole, resumed = load_agent(tmp_path / "whole" / "model.zip"), load_agent(out / "model.zip")
    a, b = whole.model.policy.state_dict(), resumed.model.policy.state_dict()
    assert all(torch.equal(a[key], b[key]) for key in a)
    assert _curve(tmp_path / "whole") == _curve(out)


def test_a_second_training_in_a_folder_in_use_is_refused_naming_the_first(tmp_path):
    out = tmp_path / "busy"
    with open(tmp_path / "first.log", "w") as log:
        first = subprocess.Popen(
            cli_command(*TRAIN[:3], "5000", *TRAIN[4:], "--out", str(out)),
            stdout=log,
            stderr=subprocess.STDOUT,
            env=environment(),
            cwd=ROOT,
        )
        try:
            deadline = time.monotonic() + 120
            while f'"pid": {first.pid}' not in ((out / "run.lock").read_text() if (out / "run.lock").exists() else ""):
                assert time.monotonic() < deadline and first.poll() is None, (tmp_path / "first.log").read_text()
                time.sleep(0.05)
            second = run_cli(*TRAIN, "--out", str(out))
        finally:
            first.send_signal(signal.SIGKILL)
            first.wait()
    assert second.returncode == 2
    assert f"in use by process {first.pid}" in second.stderr
