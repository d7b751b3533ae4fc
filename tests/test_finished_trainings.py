"""A finished training is kept: `baseline train` refuses to redo it without --force, and a
benchmark killed part-way keeps the agents it had finished (checkpoints.finished_agent)."""

from __future__ import annotations

import argparse
import dataclasses
import json

import pytest
import torch

import dvrk_gym.baselines.checkpoints as checkpoints
from dvrk_gym.baselines.checkpoints import finished_agent, settings_path
from dvrk_gym.baselines.curves import load_curve
from dvrk_gym.cli.baselines import TRAINING_STATE, add_commands
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

COMMAND = ["baseline", "train", "--algo", "sac", "--steps", "20", "--learning-starts", "10", "--resolution", "320", "180"]


def _parse(*extra: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="dvrk-gym")
    add_commands(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args([*COMMAND, "--eval-points", "1", "--no-progress", *extra])


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A folder holding a finished `baseline train` (model, settings, curve, plot)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    args = _parse("--out", str(out))
    assert args.func(args) == 0
    return out


def _written(folder):
    return {path.name: (path.read_bytes(), path.stat().st_mtime_ns) for path in sorted(folder.iterdir()) if path.name != "run.lock"}


def test_a_finished_training_run_again_is_reported_not_trained_again(finished, capsys):
    before = _written(finished)
    args = _parse("--out", str(finished))
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "nothing to do (--force trains again)" in out
    curve = load_curve(finished / "learning_curve.json")
    first, final = curve[0], curve[-1]
    assert out.startswith(f"learning curve: {first.mm_error:.2f} mm at 0 steps -> {final.mm_error:.2f} mm")  # from its file
    assert _written(finished) == before  # nothing written, nothing touched


def test_a_finished_training_of_other_settings_is_refused_without_force(finished):
    before = _written(finished)
    args = _parse("--out", str(finished), "--seed", "1")
    with pytest.raises(FileExistsError, match="finished training of other settings or other code.*--force"):
        args.func(args)
    assert _written(finished) == before


def test_a_finished_training_with_a_damaged_curve_is_refused_naming_it(finished, tmp_path):
    out = tmp_path / "damaged"
    out.mkdir()
    for path in finished.iterdir():
        (out / path.name).write_bytes(path.read_bytes())
    for text in ('{"points": 3}', '{"points": []}', '{"points": [{"env_steps": -1}]}', "[]"):
        (out / "learning_curve.json").write_text(text)
        args = _parse("--out", str(out))
        with pytest.raises(ValueError, match=r"learning_curve.json .*; give --force to train again$"):
            args.func(args)


def test_a_saved_state_that_cannot_be_resumed_is_refused_naming_the_way_out(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / TRAINING_STATE).write_bytes(b"not a state")
    args = _parse("--out", str(out))
    with pytest.raises(ValueError, match=rf"{TRAINING_STATE}.* \(--force trains from the start, replacing it\)$"):
        args.func(args)
    assert (out / TRAINING_STATE).read_bytes() == b"not a state"


def test_force_trains_again_from_the_start_even_over_a_saved_state(finished, tmp_path):
    out = tmp_path / "copy"
    out.mkdir()
    for name in ("model.zip", "model.json"):
        (out / name).write_bytes((finished / name).read_bytes())
    (out / TRAINING_STATE).write_bytes(b"not a state: --force must not try to resume it")
    args = _parse("--out", str(out), "--force")
    assert args.func(args) == 0
    assert not (out / TRAINING_STATE).exists()
    assert (out / "model.zip").read_bytes() != b"" and (out / "learning_curve.json").exists()
    same = checkpoints.load_agent(finished / "model.zip").model.policy.state_dict()
    again = checkpoints.load_agent(out / "model.zip").model.policy.state_dict()
    assert same.keys() == again.keys() and all(torch.equal(same[key], again[key]) for key in same)  # the same training again


def test_a_finished_agent_is_kept_only_for_its_own_settings_and_code(finished, monkeypatch):
    path = finished / "model.zip"
    kept = finished_agent(path, checkpoints.load_agent(path).config)
    assert kept is not None and kept.source == source_fingerprint()
    config = kept.config
    assert finished_agent(path, dataclasses.replace(config, seed=config.seed + 1)) is None
    assert finished_agent(path, dataclasses.replace(config, steps=config.steps + 1)) is None
    assert finished_agent(finished / "absent.zip", config) is None
    monkeypatch.setattr(checkpoints, "source_fingerprint", lambda: SourceFingerprint(version="0", sha256="0" * 64))
    assert finished_agent(path, config) is None  # trained by other code: train it again


def test_a_damaged_or_unrecorded_agent_is_not_kept(finished, tmp_path):
    config = checkpoints.load_agent(finished / "model.zip").config
    out = tmp_path / "damaged"
    out.mkdir()
    (out / "model.zip").write_bytes((finished / "model.zip").read_bytes()[:-100])
    (out / "model.json").write_bytes((finished / "model.json").read_bytes())
    assert finished_agent(out / "model.zip", config) is None  # cut short: its digest differs
    (out / "model.zip").write_bytes((finished / "model.zip").read_bytes())
    settings = json.loads(settings_path(out / "model.zip").read_text())
    del settings["source"]  # saved before the source was recorded
    settings_path(out / "model.zip").write_text(json.dumps(settings))
    assert finished_agent(out / "model.zip", config) is None


def test_a_model_without_its_curve_and_no_state_is_trained_again(finished, tmp_path, capsys):
    """Killed between the model and its curve before any save: nothing to resume, and not finished."""
    out = tmp_path / "cut"
    out.mkdir()
    for name in ("model.zip", "model.json"):
        (out / name).write_bytes((finished / name).read_bytes())
    args = _parse("--out", str(out))
    assert args.func(args) == 0
    assert "training again from the start" in capsys.readouterr().out
    assert load_curve(out / "learning_curve.json") == load_curve(finished / "learning_curve.json")  # the same points (times vary)
