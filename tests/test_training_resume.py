"""A training saved between episodes and resumed ends as a training never stopped, bit for bit;
a state file that cannot be that is refused clearly, before anything is allocated."""

from __future__ import annotations

import io
import json
import shutil
import zipfile

import numpy as np
import pytest
import torch

from dvrk_gym.baselines import TrainConfig, train
from dvrk_gym.baselines.resume import TrainingStateError, TrainingStateWriter
from dvrk_gym.baselines.resume.state_file import STATE_JSON, TENSORS
from dvrk_gym.envs.base import DvrkEnv

TINY = (320, 180)
FAST = {"learning_starts": 10, "batch_size": 32, "gradient_steps": 1, "policy_kwargs": {"net_arch": [32, 32]}}


def _config(agent: str = "sac_her", steps: int = 48, **fields) -> TrainConfig:
    return TrainConfig(agent=agent, steps=steps, camera_resolution=TINY, eval_points=3, curve_trials=1, overrides=dict(FAST), **fields)


def _weights(model) -> dict[str, torch.Tensor]:
    return {key: value.clone() for key, value in model.policy.state_dict().items()}


def _same_run(first, second) -> None:
    a, b = _weights(first.model), _weights(second.model)
    assert a.keys() == b.keys()
    different = [key for key in a if not torch.equal(a[key], b[key])]
    assert not different, f"weights differ: {different[:3]}"
    assert first.curve == second.curve or np.allclose(  # NaN pixel errors of pick agents compare unequal
        [[p.mm_error, p.success_rate] for p in first.curve], [[p.mm_error, p.success_rate] for p in second.curve], rtol=0, atol=0
    )
    assert [p.env_steps for p in first.curve] == [p.env_steps for p in second.curve]
    buffer_a, buffer_b = first.model.replay_buffer, second.model.replay_buffer
    assert (buffer_a.pos, buffer_a.full) == (buffer_b.pos, buffer_b.full)
    assert np.array_equal(buffer_a.actions, buffer_b.actions) and np.array_equal(buffer_a.rewards, buffer_b.rewards)
    assert first.model._n_updates == second.model._n_updates


@pytest.fixture(scope="module")
def uninterrupted():
    return train(_config(), progress=False)


@pytest.fixture
def saved_state(tmp_path):
    """The state a 48-step training leaves at 40 steps (saves every 20 steps; the last one stays)."""
    path = tmp_path / "state.zip"
    train(_config(), progress=False, state_path=path, save_every=20)
    return path


def _state_json(path) -> dict:
    with zipfile.ZipFile(path) as archive:
        return json.loads(archive.read(STATE_JSON))


def test_a_resumed_training_ends_bit_for_bit_as_one_never_stopped(uninterrupted, saved_state):
    assert _state_json(saved_state)["num_timesteps"] == 40
    resumed = train(_config(), progress=False, state_path=saved_state, save_every=20)
    _same_run(uninterrupted, resumed)
    assert resumed.env_steps == 48


def test_resuming_without_the_envs_memory_would_not_be_the_same_run(saved_state, monkeypatch):
    """The check that makes the test above able to fail: the cables' history is part of the
    state; drop it and the replayed reset observes another touch point, which is refused."""
    original = DvrkEnv.restore_carried_state

    def forget_the_cables(self, state):
        cables = self.world.cable.get_state()
        original(self, state)
        self.world.cable.set_state(cables)

    monkeypatch.setattr(DvrkEnv, "restore_carried_state", forget_the_cables)
    with pytest.raises(TrainingStateError, match="observe other values"):
        train(_config(), progress=False, state_path=saved_state)


def test_two_training_envs_resume_bit_for_bit(tmp_path):
    config = _config("sac", steps=40, n_envs=2)
    never_stopped = train(config, progress=False)
    path = tmp_path / "state.zip"
    train(config, progress=False, state_path=path, save_every=16)
    assert _state_json(path)["num_timesteps"] == 32 and len(_state_json(path)["envs"]) == 2
    _same_run(never_stopped, train(config, progress=False, state_path=path))


@pytest.mark.slow
def test_a_pick_agent_resumes_bit_for_bit_mid_way_through_its_trials(tmp_path):
    """sac_pick's episodes are trials of eight picks: its state is saved between trials only."""
    config = _config("sac_pick", steps=24)
    never_stopped = train(config, progress=False)
    path = tmp_path / "state.zip"
    train(config, progress=False, state_path=path, save_every=10)
    assert 10 <= _state_json(path)["num_timesteps"] < 24  # saved at a trial's start, once due
    _same_run(never_stopped, train(config, progress=False, state_path=path))


def test_saves_come_only_between_episodes_and_at_the_same_steps_after_a_resume():
    writer = TrainingStateWriter("unused.zip", every=10, config={}, progress=dict)
    writer.num_timesteps = 37
    writer._on_training_start()
    assert writer._due == 40
    with pytest.raises(ValueError, match="every"):
        TrainingStateWriter("unused.zip", every=0, config={}, progress=dict)
    with pytest.raises(ValueError, match="JSON"):
        TrainingStateWriter("unused.zip", every=5, config={"f": object()}, progress=dict)


def _rewrite(path, member: str, data: bytes) -> None:
    """Replace one member of the zip at ``path``."""
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members[member] = data
    with zipfile.ZipFile(path, "w") as archive:
        for name, value in members.items():
            archive.writestr(name, value)


def _edit_json(path, edit) -> None:
    state = _state_json(path)
    edit(state)
    _rewrite(path, STATE_JSON, json.dumps(state).encode())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda s: s.update(format="other/1"), "not a dvrk_gym training state"),
        (lambda s: s["source"].update(sha256="0" * 64), "written by dvrk_gym"),
        (lambda s: s.update(num_timesteps=-3), "num_timesteps"),
        (lambda s: s["buffer"].update(pos=10**9), "buffer's position"),
        (lambda s: s["envs"][0]["layers"][-1]["state"]["cable"][-1].__setitem__(0, 0.05), "observe other values"),
        (lambda s: s["envs"][0]["layers"][-1]["state"]["cable"].pop(), "state must have shape"),
        (lambda s: s["envs"][0]["layers"][-1]["state"].update(np_random={"bit_generator": "MT19937"}), "np_random"),
        (lambda s: s["envs"][0]["layers"].pop(), "stack"),
        (lambda s: s["rng"].update(numpy=[1, 2]), "TrainingStateError|ValueError|values to unpack"),
        (lambda s: s["rng"]["numpy"].__setitem__(2, 2**31 - 1), "MT19937 state"),  # numpy crashed the process on it
        (lambda s: s["rng"]["numpy"].__setitem__(2, 625), "MT19937 state"),  # numpy drew garbage from it
        (lambda s: s["rng"]["numpy"][1].__setitem__(0, 2**32), "32-bit words"),
        (lambda s: s["rng"]["python"][1].__setitem__(-1, 10**6), "TrainingStateError|ValueError|state"),
        (lambda s: s["progress"]["curve"].update(marks=[1]), "later marks"),
        (lambda s: s["progress"]["curve"]["points"][0].update(mm_error="x"), "mm_error must be a real number"),
        (lambda s: s["progress"]["curve"]["points"][0].update(env_steps=-1), "env_steps"),
        (lambda s: s["progress"].update(wall_seconds=float("nan")), "wall_seconds"),
        (lambda s: s["progress"]["curve"].update(eval_seconds=-1.0), "eval_seconds"),
    ],
)
def test_a_tampered_state_json_is_refused_naming_the_file(saved_state, edit, message):
    _edit_json(saved_state, edit)
    with pytest.raises(TrainingStateError, match=message) as caught:
        train(_config(), progress=False, state_path=saved_state)
    assert str(saved_state) in str(caught.value)


def test_a_state_written_with_other_libraries_is_refused_naming_them(saved_state):
    _edit_json(saved_state, lambda s: s["libraries"].update(torch="0.1"))
    with pytest.raises(TrainingStateError, match="torch 0.1 there"):
        train(_config(), progress=False, state_path=saved_state)


def test_numbers_too_large_for_a_float_are_refused_clearly(saved_state):
    with zipfile.ZipFile(saved_state) as archive:
        text = archive.read(STATE_JSON).decode()
    state = json.loads(text)
    state["envs"][0]["layers"][-1]["state"]["q_cmd"][0] = 12345.678
    _rewrite(saved_state, STATE_JSON, json.dumps(state).replace("12345.678", "1" + "0" * 400).encode())
    with pytest.raises(TrainingStateError, match="must hold numbers"):
        train(_config(), progress=False, state_path=saved_state)


def test_an_npy_header_claiming_a_huge_array_is_refused_before_allocating(saved_state):
    with zipfile.ZipFile(saved_state) as archive:
        name = next(n for n in archive.namelist() if n.endswith("rewards.npy"))
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (4 * 10**12,)})
    _rewrite(saved_state, name, header.getvalue())  # a header only: a few hundred bytes
    with pytest.raises(TrainingStateError, match="expected float32"):
        train(_config(), progress=False, state_path=saved_state)


@pytest.mark.slow
def test_a_worker_process_refusing_its_record_is_a_clear_error(tmp_path):
    """With one process per env, a record a worker refuses comes back as a message, and the
    worker (and the envs' closing) survive it."""
    config = _config("sac", steps=24, n_envs=2, vec_env="subproc")
    path = tmp_path / "state.zip"
    train(config, progress=False, state_path=path, save_every=8)
    _edit_json(path, lambda s: s["envs"][1]["layers"][-1]["state"]["cable"].pop())
    with pytest.raises(TrainingStateError, match="training env 1 refused its recorded reset"):
        train(config, progress=False, state_path=path)


def test_a_state_of_other_settings_names_the_settings_that_differ(saved_state):
    with pytest.raises(TrainingStateError, match="differing in seed, steps"):
        train(_config(steps=60, seed=3), progress=False, state_path=saved_state)


def test_arrays_of_another_shape_or_holding_objects_are_refused(saved_state):
    with zipfile.ZipFile(saved_state) as archive:
        name = next(n for n in archive.namelist() if n.endswith("actions.npy"))
        actions = np.load(io.BytesIO(archive.read(name)))
    for bad, message in [(actions[:-1], "expected"), (np.array([{"x": 1}] * len(actions), dtype=object), "holds object")]:
        stream = io.BytesIO()
        np.save(stream, bad, allow_pickle=True)
        copy = saved_state.with_name(f"bad_{len(message)}.zip")
        shutil.copy(saved_state, copy)
        _rewrite(copy, name, stream.getvalue())
        with pytest.raises(TrainingStateError, match=message):
            train(_config(), progress=False, state_path=copy)


def test_members_larger_than_the_model_can_hold_are_refused_before_they_are_read(saved_state):
    with zipfile.ZipFile(saved_state) as archive:
        name = next(n for n in archive.namelist() if n.endswith("rewards.npy"))
    huge = np.zeros((5_000_000, 1), dtype=np.float32)  # 20 MB inflated, a few kB deflated
    stream = io.BytesIO()
    np.save(stream, huge)
    with zipfile.ZipFile(saved_state) as archive:
        members = {n: archive.read(n) for n in archive.namelist()}
    members[name] = stream.getvalue()
    with zipfile.ZipFile(saved_state, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for member, data in members.items():
            archive.writestr(member, data)
    with pytest.raises(TrainingStateError, match="inflates to"):
        train(_config(), progress=False, state_path=saved_state)


@pytest.mark.parametrize("damage", ["truncate", "tensors", "not a zip"])
def test_a_damaged_file_is_refused_clearly(saved_state, damage):
    if damage == "truncate":
        data = saved_state.read_bytes()
        saved_state.write_bytes(data[: len(data) // 2])
    elif damage == "tensors":
        _rewrite(saved_state, TENSORS, b"\x08\x00\x00\x00\x00\x00\x00\x00{garbage")
    else:
        saved_state.write_text("hello")
    with pytest.raises(TrainingStateError, match=str(saved_state.name)):
        train(_config(), progress=False, state_path=saved_state)


def test_the_cli_names_the_state_file_and_the_default_the_package_uses():
    from dvrk_gym.baselines.resume import STATE_FILE_NAME
    from dvrk_gym.baselines.training import SAVE_EVERY
    from dvrk_gym.cli.baselines import DEFAULT_SAVE_EVERY, TRAINING_STATE

    assert (TRAINING_STATE, DEFAULT_SAVE_EVERY) == (STATE_FILE_NAME, SAVE_EVERY)


def test_a_run_stopped_after_its_model_but_before_its_curve_resumes_and_writes_them_all(tmp_path, monkeypatch, capsys):
    """The state is deleted only once every output is written: a kill while the curve is drawn
    resumes from the last save, not from nothing."""
    import argparse

    import dvrk_gym.baselines.curves as curves
    from dvrk_gym.cli.baselines import TRAINING_STATE, add_commands

    parser = argparse.ArgumentParser(prog="dvrk-gym")
    add_commands(parser.add_subparsers(dest="command", required=True))
    out = tmp_path / "run"
    command = ["baseline", "train", "--algo", "sac", "--steps", "30", "--learning-starts", "10", "--resolution", "320", "180"]
    args = parser.parse_args([*command, "--eval-points", "1", "--save-every", "10", "--out", str(out), "--no-progress"])

    def killed(*_, **__):
        raise KeyboardInterrupt

    monkeypatch.setattr(curves, "plot_curves", killed)
    with pytest.raises(KeyboardInterrupt):
        args.func(args)
    assert (out / "model.zip").exists() and (out / TRAINING_STATE).exists() and not (out / "learning_curve.png").exists()
    monkeypatch.undo()
    assert args.func(args) == 0
    assert "resumed the training saved in" in capsys.readouterr().out
    assert (out / "learning_curve.png").exists() and not (out / TRAINING_STATE).exists()


def test_an_interrupted_training_ends_its_progress_bar_so_the_next_line_is_its_own(monkeypatch, capsys):
    """Ctrl-C mid-training left the bar's line open: the command's "interrupted" note was
    printed on the end of it."""
    import dvrk_gym.baselines.training as training

    measure = training.curve_evaluator(_config("sac", 30))
    calls = []

    def interrupted_at_the_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return measure(*args, **kwargs)

    monkeypatch.setattr(training, "curve_evaluator", lambda config: interrupted_at_the_second)
    with pytest.raises(KeyboardInterrupt):
        train(_config("sac", 30), progress=True)
    err = capsys.readouterr().err
    assert "training" in err and err.endswith("\n")
