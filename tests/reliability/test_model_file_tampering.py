"""Model files damaged or edited, carelessly or with care: every one refused with ``ModelFileError``
naming the file and what is wrong, and none ever unpickled or handed to scikit-learn unchecked.

The careful edits (``model_forgery``) rewrite every size and SHA-256, as anyone can: what refuses
them is the models' own checks (shapes, finiteness, the trees' structure, the trusted types).
"""

from __future__ import annotations

import io
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import safetensors.numpy
import skops.io
from model_forgery import (
    ARRAYS,
    MANIFEST,
    edit_arrays,
    edit_manifest,
    edit_skops,
    edit_tree,
    read_members,
    resign,
    tree_nodes,
    write_members,
)
from sklearn.ensemble import ExtraTreesRegressor
from sklearn.pipeline import make_pipeline

from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.forests import ForestCalibrator, ResidualForests
from dvrk_gym.calibration.models.linear import LinearCalibrator
from dvrk_gym.calibration.models.serialization import ModelFileError
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator


def _rows(seed: int = 0, rows: int = 120) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = np.column_stack(
        [rng.uniform(-0.03, 0.03, (rows, 2)), rng.uniform(0.17, 0.2, rows), rng.uniform(-1.6, 1.6, rows), rng.uniform(-1, 1, (rows, 2))]
    )
    return X, X[:, :3] + 0.01 * np.sin(X[:, 3:])


def _small_dnn() -> DNNCalibrator:
    return DNNCalibrator(hidden_layers=2, units=8, epochs=3, progress=False)


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> dict[str, Path]:
    X, y = _rows()
    folder = tmp_path_factory.mktemp("originals")
    models = {
        "dnn": _small_dnn().fit(X, y),
        "forest": ForestCalibrator(trees=4, max_depth=6, seed=1).fit(X, y),
        "two_phase": TwoPhaseCalibrator(dnn=_small_dnn(), forests=ResidualForests(trees=3)).fit_phase1(X, y).fit_phase2(X[:60], y[:60]),
    }
    paths = {}
    for name, model in models.items():
        paths[name] = folder / f"{name}.zip"
        model.save(paths[name])
    return paths


@pytest.fixture
def saved(originals, tmp_path) -> dict[str, Path]:
    """Fresh copies of the saved models, for one test to tamper with."""
    return {name: Path(shutil.copy(path, tmp_path / path.name)) for name, path in originals.items()}


def _refused(load, path: Path, *messages: str) -> str:
    with pytest.raises(ModelFileError) as raised:
        load(path)
    text = str(raised.value)
    assert path.name in text, text
    assert any(message in text for message in messages), text
    return text


# ---------------------------------------------------------------- careless damage
def _flip_middle_bytes(path: Path) -> None:
    blob = bytearray(path.read_bytes())
    for offset in range(len(blob) // 2, len(blob) // 2 + 8):
        blob[offset] ^= 0xFF
    path.write_bytes(bytes(blob))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])


@pytest.mark.parametrize("model", ["dnn", "forest", "two_phase"])
@pytest.mark.parametrize(
    ("damage", "messages"),
    [
        (_flip_middle_bytes, ("SHA-256", "corrupt", "CRC", "not a readable zip archive")),  # not "zip": the file's name has it
        # a cut file may end inside a stored skops archive, which then passes for the zip read, without model.json
        (_truncate, ("not a readable zip archive", "no model.json; not a dvrk_gym model file")),
        (lambda path: path.write_bytes(b"PK\x03\x04 not a model file"), ("not a readable zip archive",)),
    ],
    ids=["flipped-bytes", "truncated", "not-a-zip"],
)
def test_damaged_files_are_refused(saved, model, damage, messages):
    damage(saved[model])
    _refused(type_of(model).load, saved[model], *messages)


def type_of(name: str):
    return {"dnn": DNNCalibrator, "forest": ForestCalibrator, "two_phase": TwoPhaseCalibrator}[name]


def test_an_edited_weight_fails_its_digest(saved):
    members = read_members(saved["dnn"])
    arrays = dict(safetensors.numpy.load(members[ARRAYS]))
    arrays["layer0_weight"] = arrays["layer0_weight"] + np.float32(1.0)
    members[ARRAYS] = safetensors.numpy.save(arrays)
    write_members(saved["dnn"], members)  # the manifest's digest left as it was
    _refused(DNNCalibrator.load, saved["dnn"], "fails its SHA-256 digest")


def test_a_member_of_another_size_than_declared_is_refused_before_it_is_read(saved):
    members = read_members(saved["dnn"])
    members[ARRAYS] += b"\x00" * 16
    write_members(saved["dnn"], members)
    _refused(DNNCalibrator.load, saved["dnn"], "holds", "model.json says")


def test_the_wrong_kind_version_or_layout_is_refused(saved, tmp_path):
    _refused(ForestCalibrator.load, saved["dnn"], "holds a 'dnn_calibrator' model; expected 'forest_calibrator'")
    edit_manifest(saved["forest"], lambda manifest: manifest.update(format_version=99))
    _refused(ForestCalibrator.load, saved["forest"], "format version 99; this dvrk_gym reads version 2")
    edit_manifest(saved["dnn"], lambda manifest: manifest["layout"].update(outputs=["bx_mm", "by_mm", "bz_mm"]))
    _refused(DNNCalibrator.load, saved["dnn"], "feature layout")
    _refused(LinearCalibrator.load, tmp_path / "absent.zip", "no such model file")


# ---------------------------------------------------------------- careful edits of the arrays
def _set(name: str, value):
    return lambda arrays: arrays.__setitem__(name, value(arrays[name]))


@pytest.mark.parametrize(
    ("edit", "messages"),
    [
        (_set("layer1_weight", lambda w: np.where(np.arange(w.size).reshape(w.shape) == 0, np.nan, w).astype(np.float32)), ("non-finite",)),
        (_set("layer1_weight", lambda w: np.ascontiguousarray(w[:, :-1])), ("layer1_weight", "expected float32")),
        (_set("layer0_weight", lambda w: w.astype(np.float64)), ("layer0_weight", "expected float32")),
        (lambda arrays: arrays.pop("layer0_bias"), ("missing ['layer0_bias']",)),
        (lambda arrays: arrays.update(extra=np.zeros(3)), ("unexpected ['extra']",)),
        (_set("x_scale", lambda s: -s), ("must be positive",)),
    ],
    ids=["nan-weight", "wrong-shape", "wrong-dtype", "missing-array", "extra-array", "negative-scale"],
)
def test_arrays_that_do_not_fit_the_model_are_refused(saved, edit, messages):
    edit_arrays(saved["dnn"], edit)
    _refused(DNNCalibrator.load, saved["dnn"], *messages)


def test_arrays_unlike_their_declaration_are_refused(saved):
    edit_arrays(saved["dnn"], _set("x_mean", lambda m: m[:5].copy()), declare=False)
    _refused(DNNCalibrator.load, saved["dnn"], "array 'x_mean' is float64 [5]; model.json says float64 [9]")


def test_a_two_phase_file_with_a_stray_member_is_refused(saved):
    members = read_members(saved["two_phase"])
    members["rf.stray.skops"] = members["rf.yaw+0.skops"]
    write_members(saved["two_phase"], resign(members))
    _refused(TwoPhaseCalibrator.load, saved["two_phase"], "rf.stray", "unexpected")


# ---------------------------------------------------------------- careful edits of the forests
@pytest.mark.parametrize("child", [-5, 0, 10**6])
def test_a_tree_whose_child_leaves_its_tree_or_loops_is_refused(saved, child):
    """scikit-learn follows child indices without bounds checks: unchecked, these would crash or hang."""

    def edit(nodes):
        nodes["left_child"][0] = child  # the root's child: negative, the root itself, or outside the tree

    edit_tree(saved["forest"], "forest.skops", edit, tree=2)
    _refused(ForestCalibrator.load, saved["forest"], "tree 2 children_left[0]")


def test_a_tree_splitting_on_a_feature_it_has_not_is_refused(saved):
    def edit(nodes):
        nodes["feature"][0] = 9  # the forest has 9 features: 0..8

    edit_tree(saved["forest"], "forest.skops", edit)
    _refused(ForestCalibrator.load, saved["forest"], "feature[0] = 9; expected 0..8")


def test_a_residual_forest_with_a_non_finite_leaf_is_refused(saved):
    def edit(schema, files):
        tree = tree_nodes(schema)[0]
        name = tree["content"]["content"]["values"]["file"]
        values = np.load(io.BytesIO(files[name]))
        values[-1] = np.inf
        stream = io.BytesIO()
        np.save(stream, values)
        files[name] = stream.getvalue()

    edit_skops(saved["two_phase"], "rf.yaw+0.skops", edit)
    _refused(TwoPhaseCalibrator.load, saved["two_phase"], "yaw+0: tree 0 holds non-finite")


def test_a_forest_with_other_hyper_parameters_is_refused(saved):
    def edit(schema, files):
        schema["content"]["content"]["n_jobs"] = {
            "__class__": "str",
            "__module__": "builtins",
            "__loader__": "JsonNode",
            "content": "1000000",
            "is_json": True,
        }

    edit_skops(saved["forest"], "forest.skops", edit)
    _refused(ForestCalibrator.load, saved["forest"], "hyper-parameters ['n_jobs']")


@pytest.mark.parametrize("count", ["n_outputs_", "n_features_in_"])
def test_a_forest_counting_its_outputs_in_floats_is_refused(saved, count):
    """3.0 == 3 passed the count check, and predict then failed in numpy, far from the file."""

    def edit(schema, files):
        schema["content"]["content"][count] = {  # a JSON node typed str whose JSON is a float: skops hands back 3.0
            "__class__": "str",
            "__module__": "builtins",
            "__loader__": "JsonNode",
            "content": "3.0" if count == "n_outputs_" else "9.0",
            "is_json": True,
        }

    edit_skops(saved["forest"], "forest.skops", edit)
    _refused(ForestCalibrator.load, saved["forest"], "feature and output counts")


def test_a_tree_declaring_a_billion_outputs_is_refused_before_it_is_built(saved):
    """scikit-learn allocates an array of the declared output count before it reads the nodes."""

    def edit(schema, files):
        tree_nodes(schema)[0]["__reduce__"]["args"]["content"][2]["content"] = "1000000000"

    edit_skops(saved["forest"], "forest.skops", edit)
    _refused(ForestCalibrator.load, saved["forest"], "n_outputs = 1000000000; expected an int in [1, 4096]")


def _replace_forest(path: Path, member: str, estimator) -> None:
    members = read_members(path)
    members[member] = skops.io.dumps(estimator)
    write_members(path, resign(members))


@pytest.mark.parametrize(
    ("estimator", "kind"),
    [
        (ExtraTreesRegressor(n_estimators=2, random_state=0), "sklearn.ensemble._forest.ExtraTreesRegressor"),
        (make_pipeline(ExtraTreesRegressor(n_estimators=2)), "sklearn.pipeline.Pipeline"),
    ],
    ids=["extra-trees", "pipeline"],
)
def test_types_outside_the_explicit_trusted_list_are_refused(saved, estimator, kind):
    """skops itself trusts every scikit-learn estimator by default; a model file trusts only its own list."""
    X, y = _rows()
    _replace_forest(saved["forest"], "forest.skops", estimator.fit(np.column_stack([X, X[:, 3:]]), y))
    _refused(ForestCalibrator.load, saved["forest"], f"holds a {kind}; the trusted types are")


def test_a_function_in_a_skops_member_is_refused(saved):
    _replace_forest(saved["forest"], "forest.skops", {"call": np.sum})
    _refused(ForestCalibrator.load, saved["forest"], "the trusted types are", "loader")


def test_an_object_array_in_a_skops_member_is_never_unpickled(saved):
    def edit(schema, files):
        name = tree_nodes(schema)[0]["content"]["content"]["nodes"]["file"]
        stream = io.BytesIO()
        np.save(stream, np.array([{"payload": 1}], dtype=object), allow_pickle=True)
        files[name] = stream.getvalue()

    edit_skops(saved["forest"], "forest.skops", edit)
    _refused(ForestCalibrator.load, saved["forest"], "holds objects (object); no pickle is read")  # before skops reads it


def test_a_pickle_among_the_members_is_refused_unread(saved):
    members = read_members(saved["dnn"])
    members["payload.pkl"] = pickle.dumps({"payload": 1})
    write_members(saved["dnn"], members)  # not declared
    _refused(DNNCalibrator.load, saved["dnn"], "do not match model.json")
    edit_manifest(saved["dnn"], lambda manifest: None)  # now declared, and signed: still no loader reads a .pkl
    _refused(DNNCalibrator.load, saved["dnn"], "unexpected ['payload.pkl']", "payload.pkl")


# ---------------------------------------------------------------- the retired format
def _retired_file(path: Path) -> Path:
    """A file of the retired format, as dvrk_gym wrote it before: arrays and a JSON header in an .npz."""
    metadata = json.dumps({"kind": "dnn_calibrator", "format_version": 1, "params": {}, "arrays": {}})
    np.savez(path, __metadata__=np.array(metadata), __digest__=np.array("0" * 64), x_mean=np.zeros(9))
    return path


def test_a_file_of_the_retired_format_is_refused_with_the_command_that_remakes_it(tmp_path):
    path = _retired_file(tmp_path / "dnn.npz")
    text = _refused(DNNCalibrator.load, path, "retired .npz format")
    assert "dvrk-gym calibrate --out NEW_FOLDER" in text and str(tmp_path / "pipeline_config.json") in text


def test_a_run_folder_with_only_retired_models_is_refused_not_silently_recalibrated(tmp_path):
    _retired_file(tmp_path / "two_phase.npz")
    with pytest.raises(ModelFileError, match="dvrk-gym calibrate --out"):
        load_calibrator(tmp_path, "dnn+rf")
    assert not (tmp_path / "phase1.npz").exists()  # no calibration was started


def test_manifest_json_nested_too_deeply_is_refused(saved):
    members = read_members(saved["dnn"])
    members[MANIFEST] = b"[" * 100_000 + b"]" * 100_000
    write_members(saved["dnn"], members, compression=zipfile.ZIP_DEFLATED)
    _refused(DNNCalibrator.load, saved["dnn"], "model.json is not valid JSON")


def test_a_tensor_of_a_dtype_numpy_lacks_is_refused(saved):
    """safetensors names BF16 and F8 tensors that numpy has no dtype for: a KeyError, once a 20-line traceback."""
    import struct

    members = read_members(saved["dnn"])
    data = members[ARRAYS]
    length = struct.unpack("<Q", data[:8])[0]
    header = json.loads(data[8 : 8 + length])
    header["layer0_bias"].update(dtype="BF16", shape=[header["layer0_bias"]["shape"][0] * 2])  # the same bytes
    text = json.dumps(header).encode()
    members[ARRAYS] = struct.pack("<Q", len(text)) + text + data[8 + length :]
    write_members(saved["dnn"], resign(members))
    _refused(DNNCalibrator.load, saved["dnn"], "not readable by safetensors as numpy arrays")


def test_a_folder_where_a_model_file_should_be_is_named_as_one(tmp_path):
    (tmp_path / "dnn.zip").mkdir()
    _refused(DNNCalibrator.load, tmp_path / "dnn.zip", "a folder, not a model file")


def test_a_model_file_this_process_may_not_read_is_a_permission_error_not_a_damaged_file(saved, monkeypatch):
    """A run folder moves a damaged result aside and makes it again; a whole file it may not read must not be taken for one."""
    import zipfile as zip_module

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(saved["dnn"]))

    monkeypatch.setattr(zip_module, "ZipFile", denied)
    with pytest.raises(PermissionError):
        DNNCalibrator.load(saved["dnn"])
