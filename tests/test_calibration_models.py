"""Calibration models on synthetic data: fits, the two-phase sum, files, seeds, bad inputs."""

from __future__ import annotations

import json
import shutil
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
from dvrk_gym.calibration.models.forests import ForestCalibrator, ResidualForests
from dvrk_gym.calibration.models.linear import LinearCalibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator, fit_rigid_transform
from dvrk_gym.calibration.models.serialization import ModelFileError, write_model_file
from dvrk_gym.calibration.models.tree_ensemble import TreeEnsemble
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


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """Tiny networks train several times faster on one thread than on contended cores."""
    with torch_threads(1):
        yield


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


def test_tree_ensemble_traversal_matches_sklearn(data) -> None:
    X, y = data
    forest = RandomForestRegressor(n_estimators=15, random_state=0).fit(encode_euler(X[:300]), y[:300])
    ensemble = TreeEnsemble.from_sklearn(forest)
    expected = forest.predict(encode_euler(X[300:]))
    np.testing.assert_allclose(ensemble.predict(encode_euler(X[300:])), expected, rtol=0, atol=1e-12)


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
    path = tmp_path / "model.npz"
    model.save(path)
    loaded = type(model).load(path)
    assert np.array_equal(loaded.predict(X), model.predict(X))


def test_residual_forests_round_trip_with_an_empty_group(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    base = rng.uniform(0.0, 0.07, (100, 3))
    yaw = PAPER_YAWS_RAD[rng.integers(0, 3, 100)]
    forests = ResidualForests(trees=5).fit(base, yaw, rng.normal(0, 1e-3, (100, 3)))
    forests.save(tmp_path / "rf.npz")
    loaded = ResidualForests.load(tmp_path / "rf.npz")
    query_yaw = PAPER_YAWS_RAD[np.arange(100) % 5]
    assert np.array_equal(loaded.predict(base, query_yaw), forests.predict(base, query_yaw))


def _raw(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


def _resign(path: Path, edit: Callable[[dict, dict], None]) -> None:
    """Edit a file's params/arrays and rewrite it with a valid digest (a careful forger)."""
    raw = _raw(path)
    metadata = json.loads(str(raw.pop("__metadata__")))
    raw.pop("__digest__")
    edit(metadata["params"], raw)
    write_model_file(path, metadata["kind"], metadata["params"], raw)


@pytest.fixture(scope="module")
def originals(data, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    models = _fitted_models(data)
    directory = tmp_path_factory.mktemp("originals")
    paths = {}
    for name in ("dnn", "forest", "two_phase"):
        paths[name] = directory / f"{name}.npz"
        models[name]().save(paths[name])
    return paths


@pytest.fixture
def saved(originals: dict[str, Path], tmp_path: Path) -> dict[str, Path]:
    """Fresh copies of the saved models, for one test to tamper with."""
    return {name: Path(shutil.copy(path, tmp_path / path.name)) for name, path in originals.items()}


def _flip_middle_bytes(path: Path) -> None:
    blob = bytearray(path.read_bytes())
    for offset in range(len(blob) // 2, len(blob) // 2 + 8):
        blob[offset] ^= 0xFF
    path.write_bytes(bytes(blob))


def _edit_weight_keep_digest(path: Path) -> None:
    raw = _raw(path)
    raw["layer0_weight"] = raw["layer0_weight"].copy()
    raw["layer0_weight"][0, 0] += 1.0
    np.savez(path, **raw)


def _add_array(path: Path) -> None:
    np.savez(path, **_raw(path), extra=np.zeros(3))


def _pickle_array(path: Path) -> None:
    raw = _raw(path)
    raw["layer0_bias"] = np.array([{"payload": 1}], dtype=object)
    np.savez(path, **raw)  # np.savez pickles object arrays


def _truncate(path: Path) -> None:
    blob = path.read_bytes()
    path.write_bytes(blob[: len(blob) * 2 // 3])


def _not_a_zip(path: Path) -> None:
    path.write_bytes(b"\x93NUMPY this is not a model file")


def _nan_weight_resigned(path: Path) -> None:
    def edit(params: dict, arrays: dict) -> None:
        arrays["layer1_weight"] = arrays["layer1_weight"].copy()
        arrays["layer1_weight"][0, 0] = np.nan

    _resign(path, edit)


def _wrong_shape_resigned(path: Path) -> None:
    def edit(params: dict, arrays: dict) -> None:
        arrays["layer1_weight"] = arrays["layer1_weight"][:, :-1].copy()

    _resign(path, edit)


def _wrong_dtype_resigned(path: Path) -> None:
    def edit(params: dict, arrays: dict) -> None:
        arrays["layer0_weight"] = arrays["layer0_weight"].astype(np.float64)

    _resign(path, edit)


def _missing_array_resigned(path: Path) -> None:
    _resign(path, lambda params, arrays: arrays.pop("layer0_bias"))


def _wrong_version(path: Path) -> None:
    raw = _raw(path)
    metadata = json.loads(str(raw["__metadata__"]))
    metadata["format_version"] = 99
    raw["__metadata__"] = np.array(json.dumps(metadata, sort_keys=True))
    np.savez(path, **raw)


TAMPERINGS = {
    "flipped_bytes": _flip_middle_bytes,
    "weight_edited_digest_kept": _edit_weight_keep_digest,
    "extra_array": _add_array,
    "pickled_object_array": _pickle_array,
    "truncated": _truncate,
    "not_a_zip": _not_a_zip,
    "nan_weight": _nan_weight_resigned,
    "wrong_shape": _wrong_shape_resigned,
    "wrong_dtype": _wrong_dtype_resigned,
    "missing_array": _missing_array_resigned,
    "wrong_version": _wrong_version,
}


@pytest.mark.parametrize("tampering", sorted(TAMPERINGS))
def test_tampered_dnn_file_is_refused(tampering: str, saved) -> None:
    path = saved["dnn"]
    TAMPERINGS[tampering](path)
    with pytest.raises(ModelFileError, match=path.name):
        DNNCalibrator.load(path)


def test_flipped_bytes_break_the_zip_or_the_digest(saved) -> None:
    path = saved["dnn"]
    _flip_middle_bytes(path)
    with pytest.raises(ModelFileError, match="CRC|digest|unreadable|zip"):
        DNNCalibrator.load(path)


def test_weight_edit_is_caught_by_the_digest(saved) -> None:
    _edit_weight_keep_digest(saved["dnn"])
    with pytest.raises(ModelFileError, match="digest"):
        DNNCalibrator.load(saved["dnn"])


def test_pickled_array_is_never_unpickled(saved) -> None:
    _pickle_array(saved["dnn"])
    with zipfile.ZipFile(saved["dnn"]) as archive:
        assert "layer0_bias.npy" in archive.namelist()
    with pytest.raises(ModelFileError, match="unreadable|pickle"):
        DNNCalibrator.load(saved["dnn"])


def test_wrong_kind_is_refused(saved) -> None:
    with pytest.raises(ModelFileError, match="'dnn_calibrator' model; expected 'forest_calibrator'"):
        ForestCalibrator.load(saved["dnn"])


@pytest.mark.parametrize("child", [-5, 0, 10**6])
def test_forest_with_tree_index_out_of_range_is_refused(child: int, saved) -> None:
    def edit(params: dict, arrays: dict) -> None:
        left = arrays["children_left"].copy()
        left[0] = child  # the root's child: negative, a loop to itself, or outside the tree
        arrays["children_left"] = left

    _resign(saved["forest"], edit)
    with pytest.raises(ModelFileError, match="children"):
        ForestCalibrator.load(saved["forest"])


def test_forest_with_split_feature_out_of_range_is_refused(saved) -> None:
    def edit(params: dict, arrays: dict) -> None:
        feature = arrays["feature"].copy()
        feature[0] = 9
        arrays["feature"] = feature

    _resign(saved["forest"], edit)
    with pytest.raises(ModelFileError, match="feature"):
        ForestCalibrator.load(saved["forest"])


def test_two_phase_file_with_stray_forest_array_is_refused(saved) -> None:
    _resign(saved["two_phase"], lambda params, arrays: arrays.update(rf_stray=np.zeros(2)))
    with pytest.raises(ModelFileError, match="rf_|stray|unexpected"):
        TwoPhaseCalibrator.load(saved["two_phase"])


def test_missing_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError, match="no such model file"):
        LinearCalibrator.load(tmp_path / "absent.npz")


# --- seeds ---------------------------------------------------------------------------


def test_dnn_same_seed_gives_identical_predictions_and_other_seed_differs(data) -> None:
    X, y = data
    first = _small_dnn(seed=7, epochs=5).fit(X, y).predict(X)
    again = _small_dnn(seed=7, epochs=5).fit(X, y).predict(X)
    other = _small_dnn(seed=8, epochs=5).fit(X, y).predict(X)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)


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
