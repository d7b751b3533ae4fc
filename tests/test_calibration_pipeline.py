"""The calibrators in the simulator: policy wrapper, Phase II, evaluation, the cached pipeline, CLI."""

import dataclasses
import json
import sys
from pathlib import Path
from unittest import mock

import gymnasium as gym
import numpy as np
import pytest

from dvrk_gym.calibration.benchmark import YAW_SETTINGS, format_table, touch_grid
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.models.serialization import ModelFileError
from dvrk_gym.calibration.phase2 import Phase2Data, collect_phase2
from dvrk_gym.calibration.pipeline import SETTINGS_STAMP, PipelineConfig, check_phase1_rows, read_pipeline_settings, run_calibration
from dvrk_gym.calibration.policy import CalibratedPolicy, calibrator_input
from dvrk_gym.cli.main import main
from dvrk_gym.evaluation.episodes import as_policy, evaluate_policy, load_policy_factory, run_episodes, summarize
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.run_folder import SOURCE_KEY, RunFolder
from dvrk_gym.utils.source_fingerprint import source_fingerprint

SMALL = (640, 360)


class Recorder:
    """A calibrator that remembers its input and answers a fixed base position."""

    def __init__(self, answer=(0.04, 0.04, -0.15)):
        self.answer = np.array([answer])
        self.seen = None

    def predict(self, X):
        self.seen = np.array(X)
        return self.answer


class TipOracle:
    """A perfect calibrator for a perfect robot: it knows the hidden camera pose (tests only)."""

    def __init__(self, camera):
        self.camera = camera

    def predict(self, X):
        out = []
        for row in np.atleast_2d(X):
            target = self.camera.to_world(row[:3] / self.camera.depth_scale)[0]  # the authors' triangulation is scaled
            pose = kin.pose_from_euler(np.zeros(3), *row[3:])
            out.append(target - pose[:3, 2] * kin.JAW_LENGTH_M)
        return np.array(out)


def test_calibrated_policy_rounds_yaw_and_applies_the_papers_pitch_and_roll():
    calibrator = Recorder()
    policy = CalibratedPolicy(calibrator)
    observation = {"desired_goal": np.array([0.01, 0.02, 0.18], np.float32), "observation": np.array([0] * 7 + [0.3], np.float32)}
    action = policy(observation)
    yaw, pitch, roll = calibrator.seen[0, 3:]
    assert yaw == 0.0  # 17 degrees rounds to the paper's 0
    np.testing.assert_allclose([pitch, roll], kin.paper_pitch_roll(0.0))
    np.testing.assert_allclose(action, [0.04, 0.04, -0.15, 0.0], atol=1e-7)
    np.testing.assert_allclose(calibrator_input([0, 0, 0.2], np.radians(80))[0, 3], np.pi / 2)


def test_calibrated_policy_refuses_broken_calibrators():
    with pytest.raises(TypeError, match="predict"):
        CalibratedPolicy(object())
    policy = CalibratedPolicy(Recorder(answer=(np.nan, 0.0, 0.0)))
    observation = {"desired_goal": np.zeros(3), "observation": np.zeros(8)}
    with pytest.raises(ValueError, match="finite"):
        policy(observation)


def test_a_perfect_calibrator_touches_every_centre_on_a_perfect_robot():
    # A rigid paper: the oracle's goals lie up to 0.27 mm under the paper (below), and the
    # compliant paper would slide the jaws 0.2 mm from there.
    env = gym.make("dvrk_gym/GridTouch-v0", bias="none", camera_resolution=(1920, 1080), contact="rigid")
    try:
        errors = touch_grid(env, CalibratedPolicy(TipOracle(env.unwrapped.world.camera)), yaw=0.0)
    finally:
        env.close()
    # Only the stereo detection's sub-pixel error remains: 0.1 px of disparity moves the
    # goal 0.27 mm along the tilted viewing ray, about 0.1 mm across the paper.
    assert errors.mm.max() < 0.2 and errors.mm.mean() < 0.05 and errors.pixel.max() < 1.5


def test_phase2_corrections_put_a_biased_robot_on_the_centres(tmp_path):
    # The identified instrument without its repeatability: the corrections remove its bias.
    quiet = dataclasses.replace(BIAS_PRESETS["paper"], repeatability_m=0.0)
    env = gym.make("dvrk_gym/GridTouch-v0", bias=quiet, camera_resolution=SMALL, correction_noise_m=0.0)
    try:
        oracle = TipOracle(env.unwrapped.world.camera)
        data = collect_phase2(env, oracle, yaws=np.array([0.0]), progress=False)
        assert data.X.shape == (35, 6) and np.isfinite(data.corrected).all()
        moved = np.linalg.norm(data.corrected - data.commanded, axis=1)
        assert moved.mean() > 0.5e-3  # the cables made the robot miss; the person fixed it
        before = touch_grid(env, CalibratedPolicy(oracle), yaw=0.0)
        table = dict(zip(map(tuple, np.round(data.X, 9)), data.corrected))

        class Corrected:
            def predict(self, X):
                return np.array([table[tuple(np.round(row, 9))] for row in np.atleast_2d(X)])

        after = touch_grid(env, CalibratedPolicy(Corrected()), yaw=0.0)
        assert after.mm.mean() < 0.5 * before.mm.mean()
    finally:
        env.close()
    data.save(tmp_path / "phase2.npz")
    np.testing.assert_array_equal(Phase2Data.load(tmp_path / "phase2.npz").corrected, data.corrected)


def test_run_episodes_is_reproducible_and_summaries_are_right():
    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=SMALL)
    try:
        policy = lambda obs: np.array([0.04, 0.042, -0.154, 0.0], np.float32)  # noqa: E731
        first = run_episodes(env, policy, n_episodes=3, seed=4, options=lambda i: {"circle": 10 + i}, progress=False)
        second = run_episodes(env, policy, n_episodes=3, seed=4, options=lambda i: {"circle": 10 + i}, progress=False)
    finally:
        env.close()
    assert [r.metrics for r in first] == [r.metrics for r in second]
    assert [r.final_info["circle_index"] for r in first] == [10, 11, 12]
    stats = summarize([1.0, 2.0, 3.0, 6.0])
    assert stats["mean"] == 3.0 and stats["median"] == 2.5 and stats["min"] == 1.0 and stats["max"] == 6.0
    assert stats["sem"] == pytest.approx(np.std([1, 2, 3, 6], ddof=1) / 2)
    with pytest.raises(ValueError):
        summarize([])


def test_policies_of_every_kind_are_accepted_and_bad_specs_are_clear_errors():
    class SB3Like:
        observation_space = None

        def predict(self, observation, deterministic=True):
            return np.ones(4), None

    assert np.all(as_policy(SB3Like())(None) == 1)
    assert as_policy(lambda obs: 5)(None) == 5
    with pytest.raises(TypeError):
        as_policy(3)
    for spec, message in (
        ("no_colon", "module:factory"),
        ("no_such_module_xyz:f", "cannot import"),
        ("policies_for_tests:missing", "no attribute"),
        ("policies_for_tests:NOT_CALLABLE", "not callable"),
    ):
        with pytest.raises(ValueError, match=message):
            load_policy_factory(spec)


def test_a_policy_module_in_the_current_folder_is_found_as_an_installed_command_would_look(tmp_path, monkeypatch):
    """The installed ``dvrk-gym`` has neither the current folder nor "" on its import path (as
    ``python -m`` has), so ``--policy mypolicy:make`` beside the user was "cannot import"."""
    (tmp_path / "mypolicy_beside_the_user.py").write_text("def make(env):\n    return lambda observation: 7\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    path_before = list(sys.path)
    factory = load_policy_factory("mypolicy_beside_the_user:make")
    assert factory(None)(None) == 7
    assert sys.path == path_before  # the folder was looked in, not left on the path
    monkeypatch.delitem(sys.modules, "mypolicy_beside_the_user")


@pytest.mark.parametrize(
    ("source", "spec", "message"),
    [
        ("def make(env:\n", "policy_with_a_syntax_error:make", "raised SyntaxError: .*policy_with_a_syntax_error.py, line 1"),
        (
            "raise RuntimeError('boom')\n",
            "policy_that_raises:make",
            "importing 'policy_that_raises' for --policy raised RuntimeError: boom",
        ),
        (None, "..x:y", "must look like 'package.module:factory'"),
    ],
)
def test_a_policy_module_that_fails_to_load_is_one_clear_error(source, spec, message, tmp_path, monkeypatch):
    if source is not None:
        (tmp_path / f"{spec.partition(':')[0]}.py").write_text(source)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=message):
        load_policy_factory(spec)


def test_a_factory_that_does_not_take_the_env_is_refused_and_a_factorys_own_type_error_comes_through():
    with mock.patch("gymnasium.make") as make:
        with pytest.raises(ValueError, match="must take the env as its one argument"):
            evaluate_policy("policies_for_tests:takes_nothing", "dvrk_gym/GridTouch-v0", n_episodes=1)
        make.assert_not_called()  # refused before the env is made
    with pytest.raises(TypeError, match="has no len"):  # the factory's own bug, not a misleading "must take the env"
        evaluate_policy("policies_for_tests:raises_type_error", "dvrk_gym/GridTouch-v0", n_episodes=1, camera_resolution=SMALL)


@pytest.mark.slow
def test_pipeline_runs_end_to_end_resumes_and_refuses_other_settings(tmp_path):
    config = PipelineConfig(n_trajectories=3, steps_per_trajectory=30, dnn_epochs=5, camera_resolution=SMALL)
    first = run_calibration(tmp_path, config, progress=False)
    assert set(first["models"]) == {"RBT", "DNN", "DNN+RF"}
    assert set(first["table"]["DNN"]) == {label for label, _ in YAW_SETTINGS}
    for name in ("phase1.npz", "rbt.zip", "dnn.zip", "phase2.npz", "two_phase.zip", "calibration_table.json", "calibration_error_maps.png"):
        assert (tmp_path / name).exists()
    summary = json.loads((tmp_path / "calibration_table.json").read_text())["summary"]
    assert np.isfinite(summary["DNN+RF"]["all settings"]["mm"]["mean"])
    again = run_calibration(tmp_path, config, progress=False)
    assert set(again["timings_s"]) == {"benchmark"}  # every other stage came from the cache
    np.testing.assert_array_equal(again["table"]["DNN"]["yaw 0"].mm, first["table"]["DNN"]["yaw 0"].mm)
    assert "paper" in format_table(first["table"])
    table_file = json.loads((tmp_path / "calibration_table.json").read_text())
    assert table_file["protocol"] == "paper" and table_file["paper"]["pixels_image_px"] == [1920, 1080]
    assert table_file["source"] == source_fingerprint().to_json()  # which dvrk_gym made it
    assert (tmp_path / "calibration_table.txt").read_text().startswith("Protocol: paper (the rigid body's heights lifted")
    raw = run_calibration(tmp_path, config, progress=False, protocol="raw")  # not a setting: the same folder, evaluated raw
    assert set(raw["timings_s"]) == {"benchmark"} and raw["protocol"] == "raw"
    assert (tmp_path / "calibration_table.txt").read_text().startswith("Protocol: raw (every prediction sent as it is)")
    for label, _ in YAW_SETTINGS:  # the networks' runs were sent as they were; the rigid body's were lifted 4-9 mm
        np.testing.assert_array_equal(raw["table"]["DNN"][label].mm, first["table"]["DNN"][label].mm)
        assert not np.array_equal(raw["table"]["RBT"][label].mm, first["table"]["RBT"][label].mm)
    with pytest.raises(ValueError, match=r"protocol must be one of \['paper', 'raw'\]"):
        run_calibration(tmp_path, config, progress=False, protocol="lifted")
    with pytest.raises(ValueError, match="other settings"):
        run_calibration(tmp_path, PipelineConfig(n_trajectories=4, camera_resolution=SMALL), progress=False)


def test_a_calibration_folders_stamp_reads_back_as_its_config_and_another_versions_is_refused(tmp_path):
    config = PipelineConfig(n_trajectories=3, steps_per_trajectory=30, dnn_epochs=5, bias="none", camera_resolution=SMALL)
    with RunFolder(tmp_path, dataclasses.asdict(config), stamp=SETTINGS_STAMP):  # as run_calibration stamps it
        pass
    assert SOURCE_KEY in json.loads((tmp_path / SETTINGS_STAMP).read_text())
    assert PipelineConfig.from_settings(read_pipeline_settings(tmp_path)) == config  # the readers: evaluate, debride, benchmarks
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-0.05, 0.05, (60, 3)), np.repeat(np.deg2rad([-90.0, 0.0, 90.0]), 20), np.zeros((60, 2))])
    RigidBodyCalibrator().fit(X, X[:, :3] + 0.01).save(tmp_path / "rbt.zip")
    _, settings = load_calibrator(tmp_path, "rbt")
    assert PipelineConfig.from_settings(settings) == config
    stamp = json.loads((tmp_path / SETTINGS_STAMP).read_text())
    stamp[SOURCE_KEY]["sha256"] = "f" * 64  # made by another version
    (tmp_path / SETTINGS_STAMP).write_text(json.dumps(stamp))
    with pytest.raises(ValueError, match=r"another version of dvrk_gym's simulator .*use another --out, or delete the folder"):
        run_calibration(tmp_path, config, progress=False)
    assert not (tmp_path / "phase1.npz").exists()  # refused before any stage ran
    assert PipelineConfig.from_settings(read_pipeline_settings(tmp_path)) == config  # still read
    # its models were fitted on another simulator: debride, baseline evaluate and the benchmarks refuse them
    with pytest.raises(ValueError, match=r"another version of dvrk_gym's simulator .*dvrk-gym calibrate --out NEW_FOLDER"):
        load_calibrator(tmp_path, "rbt")


def test_a_network_fitted_with_other_settings_than_its_folders_is_refused(tmp_path):
    """A dnn.zip copied in from another run (seed 1, 3 epochs) loaded beside settings saying seed 0, 5 epochs."""
    config = PipelineConfig(n_trajectories=3, steps_per_trajectory=30, dnn_epochs=5, bias="none", camera_resolution=SMALL)
    with RunFolder(tmp_path, dataclasses.asdict(config), stamp=SETTINGS_STAMP):
        pass
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-0.05, 0.05, (60, 3)), rng.uniform(-1.5, 1.5, (60, 3))])
    DNNCalibrator(hidden_layers=1, units=4, epochs=3, seed=1, progress=False).fit(X, X[:, :3]).save(tmp_path / "dnn.zip")
    with pytest.raises(ModelFileError, match="fitted with seed 1 for 3 epochs, but its folder's settings say seed 0 and 5 epochs"):
        load_calibrator(tmp_path, "dnn")
    DNNCalibrator(hidden_layers=1, units=4, epochs=5, seed=0, progress=False).fit(X, X[:, :3]).save(tmp_path / "dnn.zip")
    assert load_calibrator(tmp_path, "dnn")[0].epochs == 5


def test_a_folder_without_the_model_is_refused_unless_asked_to_calibrate(tmp_path):
    """A mistyped folder started the paper's calibration there (57 trajectories, 1,000 epochs) with one log line."""
    with pytest.raises(FileNotFoundError, match="calibratoin does not exist: .*dvrk-gym calibrate --out"):
        load_calibrator(tmp_path / "calibratoin", "rbt")
    assert not (tmp_path / "calibratoin").exists()
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="empty has no rbt.zip"):
        load_calibrator(tmp_path / "empty", "rbt")


def test_run_calibration_refuses_a_dict_for_its_config(tmp_path):
    with pytest.raises(ValueError, match="config must be a PipelineConfig"):
        run_calibration(tmp_path, {"n_trajectories": 2})
    assert not any(tmp_path.iterdir())


def test_cli_evaluates_any_policy_from_a_factory(tmp_path, capsys):
    code = main(
        [
            "evaluate",
            "--policy",
            "policies_for_tests:middle_of_the_grid",
            "--episodes",
            "2",
            "--resolution",
            "640",
            "360",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "mm_error" in out and "pixel_error" in out
    rows = json.loads((tmp_path / "evaluation.json").read_text())
    assert len(rows) == 2 and "mm_error" in rows[0]["metrics"]


def test_cli_evaluation_of_a_policy_leaves_the_calibrations_default_folder_alone(tmp_path, capsys, monkeypatch):
    """Its evaluation.json went into dvrk_gym_out/calibration, which calibrate then refused
    as a folder of files without a settings stamp."""
    monkeypatch.chdir(tmp_path)
    policy = ["evaluate", "--policy", "policies_for_tests:middle_of_the_grid", "--episodes", "1", "--resolution", "640", "360"]
    assert main([*policy, "--no-progress"]) == 0
    assert f"wrote {Path('dvrk_gym_out/evaluation/evaluation.json')}" in capsys.readouterr().out
    assert not (tmp_path / "dvrk_gym_out" / "calibration").exists()


def test_cli_reports_bad_arguments_clearly(tmp_path, capsys):
    assert main(["evaluate", "--policy", "nonsense", "--out", str(tmp_path)]) == 2
    assert "module:factory" in capsys.readouterr().err
    factory = "policies_for_tests:middle_of_the_grid"
    assert main(["evaluate", "--policy", factory, "--protocol", "raw", "--out", str(tmp_path)]) == 2
    assert "a --policy sends its own actions as they are" in capsys.readouterr().err
    assert not (tmp_path / "evaluation.json").exists()
    made = ["evaluate", "--policy", "policies_for_tests:no_policy", "--episodes", "1", "--resolution", "640", "360", "--out", str(tmp_path)]
    assert main(made) == 2  # was a 22-line traceback from the first step
    err = capsys.readouterr().err.strip()
    assert "made no policy" in err and len(err.splitlines()) == 1


def test_cli_collect_writes_phase1_data(tmp_path, capsys):
    assert main(["collect", "--trajectories", "1", "--resolution", "640", "360", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "phase1.npz").exists()
    assert "kept" in capsys.readouterr().out


def test_collect_stamps_its_folder_as_calibrate_does_and_refuses_other_settings(tmp_path, capsys):
    tiny = ["--trajectories", "1", "--resolution", "640", "360", "--no-progress"]
    assert main(["collect", *tiny, "--out", str(tmp_path)]) == 0
    collected = (tmp_path / "phase1.npz").read_bytes()
    settings = read_pipeline_settings(tmp_path)
    assert settings is not None and settings["n_trajectories"] == 1 and settings["camera_resolution"] == [640, 360]
    same = PipelineConfig(n_trajectories=1, camera_resolution=(640, 360))  # what calibrate with the same options stamps
    with RunFolder(tmp_path, dataclasses.asdict(same), stamp=SETTINGS_STAMP) as folder:  # accepted: it resumes from this Phase I
        assert folder.has("phase1.npz")
    capsys.readouterr()
    # another collection's settings (here its seed) in the same folder: refused before collecting, the data kept
    assert main(["collect", *tiny, "--seed", "1", "--force", "--out", str(tmp_path)]) == 2
    assert "seed: 0 there, 1 here" in capsys.readouterr().err
    # a calibration with other settings would have trained on this Phase I: refused too
    assert main(["calibrate", "--trajectories", "2", "--resolution", "640", "360", "--no-progress", "--out", str(tmp_path)]) == 2
    assert "n_trajectories: 1 there, 2 here" in capsys.readouterr().err
    assert (tmp_path / "phase1.npz").read_bytes() == collected and not (tmp_path / "rbt.zip").exists()


def test_asked_to_calibrate_a_folder_whose_model_is_damaged_the_pipeline_sets_it_aside_and_makes_it_again(tmp_path):
    """As ``dvrk-gym calibrate`` does; ``debride --calibrate`` refused the folder instead."""
    config = PipelineConfig(n_trajectories=3, steps_per_trajectory=30, dnn_epochs=5, bias="none", camera_resolution=SMALL)
    with RunFolder(tmp_path, dataclasses.asdict(config), stamp=SETTINGS_STAMP):
        pass
    (tmp_path / "rbt.zip").write_bytes(b"PK\x03\x04 cut short")
    with pytest.raises(ModelFileError, match="rbt.zip"):
        load_calibrator(tmp_path, "rbt")
    assert not (tmp_path / "phase1.npz").exists()  # not asked: nothing ran
    model, _ = load_calibrator(tmp_path, "rbt", calibrate_if_missing=True)
    assert isinstance(model, RigidBodyCalibrator)
    assert (tmp_path / "rbt.zip.corrupt").read_bytes() == b"PK\x03\x04 cut short"
    assert load_calibrator(tmp_path, "rbt")[0].predict(np.zeros((1, 6))).shape == (1, 3)


def test_a_phase1_too_small_to_fit_is_refused_with_what_to_change_and_a_small_one_is_warned_of(caplog):
    """A profile at 320 x 180 kept no rows and failed with "X has no rows" from deep in the
    rigid fit; three kept rows trained a DNN without a word."""
    for kept in (0, 2):
        with pytest.raises(ValueError, match=rf"Phase I kept {kept} of its 40 samples; the calibrators need at least 3: collect more"):
            check_phase1_rows(n_kept=kept, n_raw=40)
    with caplog.at_level("WARNING", logger="dvrk_gym.calibration.pipeline"):
        check_phase1_rows(n_kept=3, n_raw=93)
        assert "Phase I kept only 3 of its 93 samples (the authors kept 1939)" in caplog.text
        caplog.clear()
        check_phase1_rows(n_kept=100, n_raw=279)
        assert caplog.text == ""


def test_calibrate_again_says_its_stages_were_loaded_and_which_were_made(small_calibration, tmp_path, capsys):
    """A re-run printed exactly what the first run printed: nothing said the models came from the cache."""
    import shutil

    folder = tmp_path / "cal"
    shutil.copytree(small_calibration, folder)
    small = ["--trajectories", "2", "--epochs", "20", "--resolution", "640", "360", "--no-progress", "--out", str(folder)]
    assert main(["calibrate", *small]) == 0
    assert f"every stage loaded from {folder}" in capsys.readouterr().out
    (folder / "two_phase.zip").unlink()
    assert main(["calibrate", *small]) == 0
    assert f"made now: forests; the others loaded from {folder}" in capsys.readouterr().out


def test_a_phase1_put_in_from_another_run_is_refused_not_loaded_beside_the_models_made_from_another(small_calibration, tmp_path, capsys):
    """Another run's phase1.npz copied in was loaded (its counts printed) beside models fitted on the first one's rows."""
    import dataclasses
    import json
    import shutil

    from dvrk_gym.calibration.phase1 import Phase1Data
    from dvrk_gym.calibration.pipeline import MADE_FROM

    folder = tmp_path / "cal"
    shutil.copytree(small_calibration, folder)
    record = json.loads((folder / MADE_FROM).read_text())
    assert set(record) == {"rbt.zip", "dnn.zip", "phase2.npz", "two_phase.zip"} and set(record["two_phase.zip"]) == {
        "dnn.zip",
        "phase2.npz",
    }
    phase1 = Phase1Data.load(folder / "phase1.npz")
    other = dataclasses.replace(phase1, reported_position=phase1.reported_position + 1e-4)  # another run's rows
    other.save(folder / "phase1.npz")
    models = {name: (folder / name).read_bytes() for name in ("rbt.zip", "dnn.zip", "two_phase.zip")}
    small = ["--trajectories", "2", "--epochs", "20", "--resolution", "640", "360", "--no-progress", "--out", str(folder)]
    assert main(["calibrate", *small]) == 2
    assert "rbt.zip was made from another phase1.npz than the one in" in capsys.readouterr().err
    assert {name: (folder / name).read_bytes() for name in models} == models  # nothing lost
    (folder / MADE_FROM).unlink()  # a folder from before the record: taken as it is, and recorded
    phase1.save(folder / "phase1.npz")
    assert main(["calibrate", *small]) == 0
    assert f"every stage loaded from {folder}" in capsys.readouterr().out
    assert json.loads((folder / MADE_FROM).read_text()) == record
