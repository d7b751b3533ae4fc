"""Calibration models on synthetic data: fits, the two-phase sum, files, seeds, bad inputs."""

from __future__ import annotations

import json
import warnings
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation
from sklearn.ensemble import RandomForestRegressor

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.features import PAPER_YAWS_RAD, encode_euler, nearest_yaw_index
from dvrk_gym.calibration.models.forests import ForestCalibrator, ResidualForests, forest_predict
from dvrk_gym.calibration.models.linear import LinearCalibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator, fit_rigid_transform
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator
from dvrk_gym.utils.torch_threads import torch_threads

ROLL_WRAP_TOL_M = 2e-4  # 0.2 mm; a raw-angle encoding would see a 359.8 deg jump


def _inputs(rng: np.random.Generator, rows: int) -> np.ndarray:
    """Calibration inputs over the paper's ranges (metres, radians)."""
    position = np.column_stack([rng.uniform(-0.04, 0.03, rows), rng.uniform(-0.05, 0.02, rows), rng.uniform(0.165, 0.22, rows)])
    angles = np.column_stack(
        [
            rng.uniform(-np.pi / 2, np.pi / 2, rows),
            rng.uniform(np.radians(-15), np.radians(25), rows),
            rng.uniform(np.radians(-180), np.radians(-150), rows),
        ]
    )
    angles[:, 2] = np.angle(np.exp(1j * (angles[:, 2] + rng.choice([0.0, 0.3], rows))))
    return np.column_stack([position, angles])


def _smooth_map(X: np.ndarray) -> np.ndarray:
    """A smooth nonlinear camera-to-base map (metres) with a few-mm angle dependence."""
    position, yaw, pitch, roll = X[:, :3], X[:, 3], X[:, 4], X[:, 5]
    base = position @ np.array([[0.0, -1.0, 0.1], [-1.0, 0.0, 0.0], [0.05, 0.1, -1.0]])
    base += 0.004 * np.column_stack([np.sin(yaw), np.cos(yaw) * np.cos(roll), np.sin(pitch)])
    base += 8.0 * position[:, [1, 0, 2]] ** 2
    return base + np.array([0.03, 0.04, 0.0])


@pytest.fixture(scope="module")
def data() -> tuple[np.ndarray, np.ndarray]:
    X = _inputs(np.random.default_rng(0), 400)
    return X, _smooth_map(X)


def _small_dnn(seed: int = 0, epochs: int = 40) -> DNNCalibrator:
    return DNNCalibrator(hidden_layers=2, units=32, epochs=epochs, batch_size=64, learning_rate=3e-3, seed=seed, progress=False)


@pytest.fixture(scope="module")
def two_phase(data: tuple[np.ndarray, np.ndarray]) -> TwoPhaseCalibrator:
    X, y = data
    model = TwoPhaseCalibrator(dnn=_small_dnn(), forests=ResidualForests(trees=10, seed=0))
    model.fit_phase1(X, y)
    return model.fit_phase2(X[:150], y[:150] + 0.001)


# --- features ------------------------------------------------------------------------


def test_nearest_yaw_index_uses_wrapped_distance() -> None:
    yaws_deg = np.array([-90.0, -67.4, -67.6, 22.4, 22.6, 90.0, 100.0, 179.0, -179.0, 270.0])
    assert nearest_yaw_index(np.radians(yaws_deg)).tolist() == [0, 1, 0, 2, 3, 4, 4, 4, 0, 0]


def test_euler_encoding_is_continuous_across_the_roll_wrap() -> None:
    X = np.array([[0.0, 0.0, 0.2, 0.1, 0.05, np.radians(179.9)], [0.0, 0.0, 0.2, 0.1, 0.05, np.radians(-179.9)]])
    features = encode_euler(X)
    assert np.abs(features[0] - features[1]).max() < 4e-3


# --- fits ----------------------------------------------------------------------------


def test_rigid_fit_recovers_known_per_yaw_transforms() -> None:
    rng = np.random.default_rng(1)
    X = _inputs(rng, 250)
    X[:, 3] = PAPER_YAWS_RAD[np.arange(250) % 5] + rng.uniform(-0.2, 0.2, 250)
    rotations = Rotation.random(5, random_state=2).as_matrix()
    translations = rng.uniform(-0.1, 0.1, (5, 3))
    groups = np.arange(250) % 5
    y = np.einsum("nij,nj->ni", rotations[groups], X[:, :3]) + translations[groups]
    model = RigidBodyCalibrator().fit(X, y)
    np.testing.assert_allclose(model.rotations_, rotations, atol=1e-9)
    np.testing.assert_allclose(model.translations_, translations, atol=1e-9)
    np.testing.assert_allclose(model.predict(X), y, atol=1e-9)
    assert np.allclose(np.linalg.det(model.rotations_), 1.0)


def test_rigid_group_with_fewer_than_three_rows_uses_all_data_fit(data) -> None:
    X, y = data
    X = X.copy()
    X[:, 3] = np.where(np.arange(len(X)) < 2, PAPER_YAWS_RAD[4], PAPER_YAWS_RAD[0])
    model = RigidBodyCalibrator().fit(X, y)
    rotation, translation = fit_rigid_transform(X[:, :3], y)
    np.testing.assert_allclose(model.rotations_[4], rotation, atol=1e-12)
    np.testing.assert_allclose(model.translations_[4], translation, atol=1e-12)
    assert model.group_rows_.tolist() == [len(X) - 2, 0, 0, 0, 2]


@pytest.mark.parametrize("layout", ["same point", "a line"])
def test_rigid_group_whose_rows_span_no_plane_uses_all_data_fit(data, layout) -> None:
    """Three rows at one point (or on a line) fix no rotation: their own fit was arbitrary (57.6 mm off)."""
    X, y = data
    X = X.copy()
    X[:, 3] = np.where(np.arange(len(X)) < 4, PAPER_YAWS_RAD[0], PAPER_YAWS_RAD[2])
    X[:4, :3] = X[0, :3] if layout == "same point" else X[0, :3] + np.outer(np.arange(4), [0.001, 0.002, 0.0])
    model = RigidBodyCalibrator().fit(X, y)
    rotation, translation = fit_rigid_transform(X[:, :3], y)
    np.testing.assert_allclose(model.rotations_[0], rotation, atol=1e-12)
    np.testing.assert_allclose(model.translations_[0], translation, atol=1e-12)
    with pytest.raises(ValueError, match="lie on a line"):
        RigidBodyCalibrator().fit(X[:4], y[:4])


@pytest.mark.parametrize(("column", "scale", "message"), [(0, 1e3, "positions reach .*expected metres"), (3, 180 / np.pi, "angles reach")])
def test_calibrators_refuse_millimetres_and_degrees(data, column, scale, message) -> None:
    X, y = data
    wrong = X.copy()
    wrong[:, column if column < 3 else slice(3, 6)] *= scale
    for model in (RigidBodyCalibrator(), LinearCalibrator(), DNNCalibrator(epochs=1, progress=False)):
        with pytest.raises(ValueError, match=message):
            model.fit(wrong, y)


def test_calibrators_refuse_targets_in_millimetres_and_forests_a_yaw_in_degrees(data) -> None:
    """Only the inputs were checked: y in millimetres fitted a model sending mm commands, and a
    yaw of 30 "degrees" fell in the -90 degree forest."""
    from dvrk_gym.calibration.models.forests import ResidualForests
    from dvrk_gym.calibration.policy import calibrator_input

    X, y = data
    for model in (RigidBodyCalibrator(), LinearCalibrator(), DNNCalibrator(epochs=1, progress=False)):
        with pytest.raises(ValueError, match="y's positions reach .*expected metres"):
            model.fit(X, y * 1e3)
    with pytest.raises(ValueError, match="yaw's angles reach .*expected radians"):
        ResidualForests(trees=2).fit(y, np.degrees(X[:, 3]), np.zeros_like(y))
    with pytest.raises(ValueError, match="residual's positions reach"):
        ResidualForests(trees=2).fit(y, X[:, 3], np.full_like(y, 5.0))
    with pytest.raises(ValueError, match="radians"):
        calibrator_input(np.array([0.0, 0.0, 0.15]), 30.0)
    assert calibrator_input(np.array([0.0, 0.0, 0.15]), 0.5)[0, 3] == pytest.approx(np.pi / 4)


def test_the_dnn_is_float32_whatever_torchs_default_dtype(data) -> None:
    X, y = data
    reference = DNNCalibrator(epochs=2, seed=0, progress=False).fit(X, y).predict(X)
    default = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)  # it failed: "mat1 and mat2 must have the same dtype"
    try:
        np.testing.assert_array_equal(DNNCalibrator(epochs=2, seed=0, progress=False).fit(X, y).predict(X), reference)
    finally:
        torch.set_default_dtype(default)


def test_dnn_fits_smooth_map_well_under_its_variance(data) -> None:
    X, y = data
    model = DNNCalibrator(hidden_layers=2, units=32, epochs=100, batch_size=100, learning_rate=1e-2, progress=False).fit(X[:300], y[:300])
    error = np.mean(np.sum((model.predict(X[300:]) - y[300:]) ** 2, axis=1))
    variance = np.mean(np.sum((y[300:] - y[300:].mean(axis=0)) ** 2, axis=1))
    assert error < 0.01 * variance
    assert model.loss_history_[-1] < model.loss_history_[0]


def test_linear_quaternion_and_euler_fit_an_affine_map_exactly() -> None:
    X = _inputs(np.random.default_rng(3), 100)
    y = X[:, :3] @ np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) + 0.02
    for angles in ("euler", "quaternion"):
        np.testing.assert_allclose(LinearCalibrator(angles).fit(X, y).predict(X), y, atol=1e-12)


def test_residual_forests_reduce_a_known_residual() -> None:
    rng = np.random.default_rng(4)
    base = rng.uniform([0.005, 0.011, -0.17], [0.07, 0.074, -0.158], (600, 3))
    yaw = PAPER_YAWS_RAD[rng.integers(0, 4, 600)]  # no rows at +90 deg
    residual = 0.002 * np.column_stack([np.sin(80 * base[:, 0]), np.cos(60 * base[:, 1]), np.sin(yaw)])
    forests = ResidualForests(trees=30, seed=0).fit(base[:500], yaw[:500], residual[:500])
    error = np.mean(np.sum((forests.predict(base[500:], yaw[500:]) - residual[500:]) ** 2, 1))
    assert error < 0.1 * np.mean(np.sum(residual[500:] ** 2, axis=1))
    assert forests.forests_[4] is None
    assert np.array_equal(forests.predict(base[:3], np.full(3, PAPER_YAWS_RAD[4])), np.zeros((3, 3)))


def test_forest_prediction_is_scikit_learns_bit_for_bit(data) -> None:
    X, y = data
    forest = RandomForestRegressor(n_estimators=15, random_state=0).fit(encode_euler(X[:300]), y[:300])
    assert np.array_equal(forest_predict(forest, encode_euler(X[300:])), forest.predict(encode_euler(X[300:])))
    model = ForestCalibrator(trees=15, seed=0).fit(X[:300], y[:300])
    assert np.array_equal(model.predict(X[300:]), forest.predict(encode_euler(X[300:])))  # fitted as before: same forest


def test_two_phase_prediction_is_dnn_plus_forest_residual(two_phase, data) -> None:
    X, _ = data
    dnn_base = two_phase.dnn.predict(X)
    expected = dnn_base + two_phase.forests.predict(dnn_base, X[:, 3])
    assert np.array_equal(two_phase.predict(X), expected)
    assert not np.allclose(expected, dnn_base)


def test_two_phase_with_phase1_only_equals_the_dnn(two_phase, data) -> None:
    X, _ = data
    phase1_only = TwoPhaseCalibrator(dnn=two_phase.dnn)
    assert np.array_equal(phase1_only.predict(X), two_phase.dnn.predict(X))


def test_phase2_learns_the_correction_at_the_phase2_targets(data) -> None:
    X, y = data
    model = TwoPhaseCalibrator(dnn=_small_dnn(), forests=ResidualForests(trees=30, seed=0))
    model.fit_phase1(X, y)
    corrected = y[:200] + np.array([0.002, -0.001, 0.0005])  # a constant 2.3 mm offset
    before = np.abs(model.predict(X[:200]) - corrected).mean()
    after = np.abs(model.fit_phase2(X[:200], corrected).predict(X[:200]) - corrected).mean()
    assert after < 0.5 * before


@pytest.mark.parametrize(
    "make",
    [
        lambda: _small_dnn(),
        lambda: LinearCalibrator("euler"),
        lambda: LinearCalibrator("quaternion"),
    ],
    ids=["dnn", "linear_euler", "linear_quaternion"],
)
def test_roll_wrap_gives_nearly_the_same_prediction(make, data) -> None:
    X, y = data
    model = make().fit(X, y)
    pair = np.array([[0.0, -0.01, 0.19, 0.2, 0.1, np.radians(179.9)], [0.0, -0.01, 0.19, 0.2, 0.1, np.radians(-179.9)]])
    prediction = model.predict(pair)
    assert np.abs(prediction[0] - prediction[1]).max() < ROLL_WRAP_TOL_M


# --- files ---------------------------------------------------------------------------


def _fitted_models(data) -> dict[str, Callable[[], object]]:
    X, y = data
    return {
        "rigid": lambda: RigidBodyCalibrator().fit(X, y),
        "linear_euler": lambda: LinearCalibrator("euler").fit(X, y),
        "linear_quaternion": lambda: LinearCalibrator("quaternion").fit(X, y),
        "forest": lambda: ForestCalibrator(trees=5, max_depth=6, seed=1).fit(X, y),
        "dnn": lambda: _small_dnn(epochs=3).fit(X, y),
        "two_phase_phase1": lambda: TwoPhaseCalibrator(dnn=_small_dnn(epochs=3)).fit_phase1(X, y),
        "two_phase": lambda: (
            TwoPhaseCalibrator(dnn=_small_dnn(epochs=3), forests=ResidualForests(trees=5)).fit_phase1(X, y).fit_phase2(X[:80], y[:80])
        ),
    }


MODEL_NAMES = ["rigid", "linear_euler", "linear_quaternion", "forest", "dnn", "two_phase_phase1", "two_phase"]


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_save_load_round_trip_predicts_identically(name, data, tmp_path: Path) -> None:
    X, _ = data
    model = _fitted_models(data)[name]()
    path = tmp_path / "model.zip"
    model.save(path)
    loaded = type(model).load(path)
    assert np.array_equal(loaded.predict(X), model.predict(X))


def test_residual_forests_round_trip_with_an_empty_group(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    base = rng.uniform(0.0, 0.07, (100, 3))
    yaw = PAPER_YAWS_RAD[rng.integers(0, 3, 100)]
    forests = ResidualForests(trees=5).fit(base, yaw, rng.normal(0, 1e-3, (100, 3)))
    forests.save(tmp_path / "rf.zip")
    loaded = ResidualForests.load(tmp_path / "rf.zip")
    query_yaw = PAPER_YAWS_RAD[np.arange(100) % 5]
    assert np.array_equal(loaded.predict(base, query_yaw), forests.predict(base, query_yaw))


def test_a_model_file_is_a_zip_of_json_safetensors_and_skops(data, tmp_path: Path) -> None:
    path = tmp_path / "two_phase.zip"
    _fitted_models(data)["two_phase"]().save(path)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        manifest = json.loads(archive.read("model.json"))
    assert names == [
        "model.json",
        "arrays.safetensors",
        "rf.yaw+0.skops",
        "rf.yaw+45.skops",
        "rf.yaw+90.skops",
        "rf.yaw-45.skops",
        "rf.yaw-90.skops",
    ]
    assert (manifest["format"], manifest["format_version"], manifest["kind"]) == ("dvrk_gym.model", 2, "two_phase_calibrator")
    assert manifest["layout"]["inputs"] == ["cx_m", "cy_m", "cz_m", "yaw_rad", "pitch_rad", "roll_rad"]
    assert manifest["layout"]["phase2"]["groups_deg"] == [-90, -45, 0, 45, 90]
    assert manifest["arrays"]["dnn.layer0_weight"] == {"shape": [32, 9], "dtype": "float32"}
    assert manifest["params"]["forests"]["trees"] == 5


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_two_fits_with_the_same_seed_save_identical_files(name, data, tmp_path: Path) -> None:
    """Byte for byte, forests too: skops names arrays by id() and dates its members, which
    the saved file does not keep (two fits are two sets of objects, with other ids)."""
    first, second = _fitted_models(data)[name](), _fitted_models(data)[name]()
    first.save(tmp_path / "a.zip")
    second.save(tmp_path / "b.zip")
    assert (tmp_path / "a.zip").read_bytes() == (tmp_path / "b.zip").read_bytes()


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_a_loaded_model_saved_again_gives_the_same_bytes(name, data, tmp_path: Path) -> None:
    """A tree skops had loaded kept heap garbage in its node records' padding, which numpy
    writes: each save of a loaded forest differed, and carried heap addresses."""
    model = _fitted_models(data)[name]()
    model.save(tmp_path / "fitted.zip")
    type(model).load(tmp_path / "fitted.zip").save(tmp_path / "again.zip")
    type(model).load(tmp_path / "again.zip").save(tmp_path / "third.zip")
    assert (tmp_path / "again.zip").read_bytes() == (tmp_path / "fitted.zip").read_bytes() == (tmp_path / "third.zip").read_bytes()


# --- seeds ---------------------------------------------------------------------------


def test_dnn_same_seed_gives_identical_predictions_and_other_seed_differs(data) -> None:
    X, y = data
    first = _small_dnn(seed=7, epochs=5).fit(X, y).predict(X)
    again = _small_dnn(seed=7, epochs=5).fit(X, y).predict(X)
    other = _small_dnn(seed=8, epochs=5).fit(X, y).predict(X)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)


def test_dnn_weights_and_predictions_do_not_depend_on_the_callers_torch_threads() -> None:
    # The paper's 3 x 300 net on 2,000 rows: wide enough that 2 threads split its products
    # (and change their last bits) where 1 does not; the fit and predict pin one thread.
    X = _inputs(np.random.default_rng(5), 2000)
    y = _smooth_map(X)
    runs = []
    for threads in (1, 2):
        with torch_threads(threads):
            model = DNNCalibrator(epochs=30, seed=0, progress=False).fit(X, y)
            runs.append((model.loss_history_, model.predict(X), np.concatenate([model.predict(X[i : i + 1]) for i in range(50)])))
            assert torch.get_num_threads() == threads  # restored after each call
    for single, double in zip(runs[0], runs[1], strict=True):
        assert np.array_equal(single, double)


def test_forests_same_seed_gives_identical_predictions(data) -> None:
    X, y = data
    first = ForestCalibrator(trees=5, seed=3).fit(X, y).predict(X)
    again = ForestCalibrator(trees=5, seed=3).fit(X, y).predict(X)
    assert np.array_equal(first, again)


def test_dnn_training_leaves_torch_global_rng_untouched(data) -> None:
    X, y = data
    state = torch.random.get_rng_state()
    _small_dnn(epochs=2).fit(X, y)
    assert torch.equal(torch.random.get_rng_state(), state)


# --- bad inputs ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [
        RigidBodyCalibrator,
        LinearCalibrator,
        lambda: ForestCalibrator(trees=2),
        lambda: _small_dnn(epochs=1),
        lambda: TwoPhaseCalibrator(dnn=_small_dnn(epochs=1)),
    ],
    ids=["rigid", "linear", "forest", "dnn", "two_phase"],
)
def test_bad_inputs_raise_value_error(make, data) -> None:
    X, y = data
    with pytest.raises(ValueError, match="before fit"):
        make().predict(X)
    with pytest.raises(ValueError, match=r"shape \(400, 5\)"):
        make().fit(X[:, :5], y)
    with pytest.raises(ValueError, match="rows"):
        make().fit(X, y[:-1])
    bad = X.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="row 3 is not finite"):
        make().fit(bad, y)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "TwoPhaseCalibrator.fit", UserWarning)  # its Phase I only: tested elsewhere
        model = make().fit(X, y)
    with pytest.raises(ValueError, match="not finite"):
        model.predict(bad)
    with pytest.raises(ValueError, match="expected \\(N, 6\\)"):
        model.predict(X[0])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"hidden_layers": 0},
        {"units": 2.5},
        {"activation": "gelu"},
        {"epochs": -1},
        {"batch_size": 0},
        {"learning_rate": float("nan")},
    ],
)
def test_bad_dnn_hyper_parameters_raise_value_error(kwargs) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        DNNCalibrator(**kwargs)


def test_phase2_before_phase1_raises_value_error(data) -> None:
    X, y = data
    with pytest.raises(ValueError, match="before fit_phase1"):
        TwoPhaseCalibrator(dnn=_small_dnn()).fit_phase2(X, y)


def test_residual_forests_reject_mismatched_yaw(data) -> None:
    _, y = data
    with pytest.raises(ValueError, match="yaw has 3 values"):
        ResidualForests(trees=2).fit(y, np.zeros(3), y)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"dnn": "foo"}, "dnn must be a regressor"), ({"forests": "foo"}, "forests must be ResidualForests"), ({"seed": 1.5}, "seed must be")],
)
def test_the_two_phase_calibrator_refuses_parts_that_are_not(kwargs, message) -> None:
    """They failed later, in vars() or on a missing attribute, far from the argument."""
    with pytest.raises(ValueError, match=message):
        TwoPhaseCalibrator(**kwargs)
