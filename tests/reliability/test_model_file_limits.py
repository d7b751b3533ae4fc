"""Model, data and agent files from elsewhere: every size bounded before anything is allocated.

A forger can write valid digests (they are no signature), so each test writes a file whose
header is consistent and whose sizes are not: the load must refuse it quickly, naming
what is wrong, and without growing the process.
"""

import io
import json
import struct
import time
import zipfile
from pathlib import Path

import numpy as np
import psutil
import pytest
from model_forgery import ARRAYS, MANIFEST, edit_manifest, edit_params, edit_skops, read_members, resign, write_members

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.forests import ForestCalibrator
from dvrk_gym.calibration.models.serialization import ModelFileError
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member

GIB = 2**30


def _bounded(load, path):
    """Run ``load(path)``; the error it raised, checked to come fast and without growing the process by 100 MB."""
    process = psutil.Process()
    before, start = process.memory_info().rss, time.perf_counter()
    with pytest.raises((ModelFileError, ValueError)) as raised:
        load(path)
    assert time.perf_counter() - start < 20.0
    assert process.memory_info().rss - before < 100 * 2**20
    return str(raised.value)


def _rows(rows: int = 60) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.column_stack([rng.uniform(-0.03, 0.03, (rows, 2)), rng.uniform(0.17, 0.2, rows), rng.uniform(-1, 1, (rows, 3))])


@pytest.fixture(scope="module")
def model_files(tmp_path_factory) -> dict[str, bytes]:
    X = _rows()
    folder = tmp_path_factory.mktemp("models")
    DNNCalibrator(hidden_layers=1, units=8, epochs=2, progress=False).fit(X, X[:, :3] + 0.01).save(folder / "dnn.zip")
    ForestCalibrator(trees=2).fit(X, X[:, :3]).save(folder / "forest.zip")
    return {name: (folder / f"{name}.zip").read_bytes() for name in ("dnn", "forest")}


@pytest.fixture
def dnn_file(model_files, tmp_path) -> Path:
    path = tmp_path / "forged.zip"
    path.write_bytes(model_files["dnn"])
    return path


@pytest.fixture
def forest_file(model_files, tmp_path) -> Path:
    path = tmp_path / "forged.zip"
    path.write_bytes(model_files["forest"])
    return path


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"hidden_layers": 3e7}, r"hidden_layers must be an int in \[1, 16\], got 30000000.0"),
        ({"hidden_layers": 30_000_000}, r"hidden_layers must be an int in \[1, 16\], got 30000000"),
        ({"units": 10**9}, r"units must be an int in \[1, 4096\]"),
        ({"hidden_layers": 16, "units": 4096}, "parameters; at most"),
        ({"hidden_layers": "3"}, "hidden_layers must be an int"),
        ({"hidden_layers": True}, "hidden_layers must be an int"),
        ({"epochs": -1}, "epochs must be"),
        ({"activation": "__import__('os')"}, "activation must be one of"),
    ],
)
def test_a_dnn_header_out_of_bounds_is_refused_before_anything_is_built(dnn_file, params, message):
    text = _bounded(DNNCalibrator.load, edit_params(dnn_file, **params))
    assert "forged.zip" in text
    assert pytest.importorskip("re").search(message, text), text


def test_a_dnn_header_that_does_not_fit_its_arrays_is_refused(dnn_file):
    text = _bounded(DNNCalibrator.load, edit_params(dnn_file, units=9))
    assert "layer0_weight" in text and "expected float32 (9, 9)" in text


def test_a_forest_header_with_a_billion_trees_is_refused(forest_file):
    text = _bounded(ForestCalibrator.load, edit_params(forest_file, trees=10**9))
    assert "trees must be an int in [1, 10000]" in text


def _zip_of(path: Path, members: dict[str, bytes], compression=zipfile.ZIP_STORED) -> Path:
    with zipfile.ZipFile(path, "w", compression=compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def _deflated_zeros(path, member: str, total_bytes: int, others: dict[str, bytes] | None = None):
    """A zip (a path or a stream) whose member ``member`` is ``total_bytes`` zeros, deflated (a few MB per GB)."""
    zeros = bytes(64 * 2**20)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for name, data in (others or {}).items():
            archive.writestr(name, data)
        with archive.open(member, "w", force_zip64=True) as stream:
            for _ in range(total_bytes // len(zeros)):
                stream.write(zeros)
    return path


def _npy_bytes(array: np.ndarray) -> bytes:
    stream = io.BytesIO()
    np.save(stream, array, allow_pickle=False)
    return stream.getvalue()


def test_a_member_that_inflates_from_1_mb_to_1_gb_is_refused_unread(tmp_path):
    path = _deflated_zeros(tmp_path / "bomb.zip", ARRAYS, GIB)
    assert path.stat().st_size < 8 * 2**20  # a few MB on disk
    text = _bounded(DNNCalibrator.load, path)
    assert "inflates to 1,073,741,824 bytes" in text and "at most 268,435,456" in text


def test_a_skops_member_whose_own_member_inflates_to_1_gb_is_refused_unread(forest_file):
    members = read_members(forest_file)
    inner = _deflated_zeros(io.BytesIO(), "0.npy", GIB, {"schema.json": read_members(io.BytesIO(members["forest.skops"]))["schema.json"]})
    members["forest.skops"] = inner.getvalue()
    write_members(forest_file, resign(members))
    text = _bounded(ForestCalibrator.load, forest_file)
    assert "forest.skops" in text and "inflates to 1,073,741,824 bytes" in text and "at most 134,217,728" in text


def test_a_skops_array_header_declaring_16_gib_over_64_bytes_is_refused_before_numpy_reserves_it(forest_file):
    """numpy reserves what an ``.npy`` header declares before it reads the data: a 22 KB file
    raised the process's address space by 16 GiB (untouched pages, so not its RSS) before
    skops failed at the missing bytes; 2**32 elements gave a MemoryError."""

    def declare_huge(schema: dict, files: dict[str, bytes]) -> None:
        name = sorted(name for name in files if name.endswith(".npy"))[-1]
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (2**31,)})
        files[name] = header.getvalue() + bytes(64)

    edit_skops(forest_file, "forest.skops", declare_huge)
    text = _bounded(ForestCalibrator.load, forest_file)
    assert "declares (2147483648,) float64 (17,179,869,184 bytes) but holds 64 bytes" in text


def test_a_safetensors_header_declaring_8_gb_over_32_bytes_is_refused_before_allocation(dnn_file):
    header = json.dumps({"x_mean": {"dtype": "F64", "shape": [10**9], "data_offsets": [0, 8 * 10**9]}}).encode()
    members = read_members(dnn_file)
    members[ARRAYS] = struct.pack("<Q", len(header)) + header + bytes(32)
    write_members(dnn_file, resign(members))
    assert "arrays.safetensors is not readable by safetensors" in _bounded(DNNCalibrator.load, dnn_file)


def test_a_manifest_declaring_a_huge_array_is_refused_before_any_member_is_read(dnn_file):
    edit_manifest(dnn_file, lambda manifest: manifest["arrays"]["x_mean"].update(shape=[10**6, 10**6]))
    assert "declares shape [1000000, 1000000]: over 268,435,456 bytes" in _bounded(DNNCalibrator.load, dnn_file)


def test_a_skops_schema_nested_too_deeply_is_refused(forest_file):
    members = read_members(forest_file)
    members["forest.skops"] = _zip_of(io.BytesIO(), {"schema.json": b"[" * 100_000 + b"]" * 100_000}).getvalue()
    write_members(forest_file, resign(members))
    assert "unreadable skops archive" in _bounded(ForestCalibrator.load, forest_file)


def test_a_skops_schema_of_another_protocol_is_refused(forest_file):
    edit_skops(forest_file, "forest.skops", lambda schema, files: schema.update(protocol=99))
    assert "skops protocol 99; expected one of [2]" in _bounded(ForestCalibrator.load, forest_file)


@pytest.mark.parametrize(
    ("members", "message"),
    [
        ({"notes.txt": b"hello"}, "no model.json; not a dvrk_gym model file"),
        ({f"a{i}.skops": b"" for i in range(65)}, "65 members; at most 64"),
        ({MANIFEST: b"[]"}, "is not a dvrk_gym.model manifest"),
    ],
    ids=["no-manifest", "too-many-members", "not-a-manifest"],
)
def test_archives_that_are_not_model_files_are_refused(tmp_path, members, message):
    text = _bounded(DNNCalibrator.load, _zip_of(tmp_path / "odd.zip", members))
    assert message in text


def test_truncated_and_non_zip_files_are_refused(dnn_file, tmp_path):
    cut = tmp_path / "cut.zip"
    cut.write_bytes(dnn_file.read_bytes()[: dnn_file.stat().st_size // 2])
    assert "not a readable zip archive" in _bounded(DNNCalibrator.load, cut)
    text_file = tmp_path / "text.zip"
    text_file.write_text("not a model")
    assert "not a readable zip archive" in _bounded(DNNCalibrator.load, text_file)


# ---------------------------------------------------------------- data records (.npz)
def test_data_records_are_read_within_the_same_limits(tmp_path):
    path = _deflated_zeros(tmp_path / "phase2.npz", "circle.npy", 5 * 64 * 2**20)
    assert "inflates to" in _bounded(Phase2Data.load, path)


def test_a_data_record_npy_header_larger_than_its_bytes_is_refused(tmp_path):
    data = bytearray(_npy_bytes(np.zeros(4)))
    header = data.replace(b"(4,)", b"(1000000000,)", 1)  # claims 8 GB, holds 32 bytes
    path = _zip_of(tmp_path / "lying.npz", {"circle.npy": bytes(header)})
    assert "declares (1000000000,) float64 (8,000,000,000 bytes) but holds" in _bounded(Phase2Data.load, path)


@pytest.mark.parametrize(
    ("member", "message"),
    [(b"\x93NUMPY garbage", "no valid npy header"), (None, "never pickles")],
    ids=["bad-header", "object-array"],
)
def test_a_data_record_that_is_not_plain_arrays_is_refused(tmp_path, member, message):
    if member is None:
        stream = io.BytesIO()
        np.save(stream, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        member = stream.getvalue()
    assert message in _bounded(Phase2Data.load, _zip_of(tmp_path / "odd.npz", {"circle.npy": member}))


def test_read_member_stops_at_the_limit_even_if_the_directory_allows_more(tmp_path):
    path = _zip_of(tmp_path / "a.zip", {"big": bytes(3 * 2**20)})
    limits = ArchiveLimits(max_member_bytes=4 * 2**20)
    with open_archive(path, limits) as archive:
        assert len(read_member(archive, "big", limits)) == 3 * 2**20
    with open_archive(path) as archive, pytest.raises(ArchiveLimitError, match="beyond"):
        read_member(archive, "big", ArchiveLimits(max_member_bytes=2**20))


# ---------------------------------------------------------------- agent files (SB3 zip + settings JSON)
def _agent_files(folder: Path, members: dict[str, bytes], **settings) -> Path:
    from dvrk_gym.baselines.checkpoints import FORMAT
    from dvrk_gym.baselines.training import TrainConfig
    from dvrk_gym.baselines.wrappers import GOAL_CENTER_M, GOAL_HALF_RANGE_M

    values = {
        "format": FORMAT,
        "config": TrainConfig(agent="sac", steps=10, camera_resolution=(320, 180)).to_dict(),
        "policy_kwargs": {"net_arch": [8, 8], "use_sde": False},
        "goal_scaling": {"center_m": list(GOAL_CENTER_M), "half_range_m": GOAL_HALF_RANGE_M},
        "env_steps": 10,
        **settings,
    }
    (folder / "model.json").write_text(json.dumps(values))
    return _zip_of(folder / "model.zip", members)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"policy_kwargs": {"net_arch": [30_000_000]}}, r"net_arch\[0\] must be an int in \[1, 4096\]"),
        ({"policy_kwargs": {"net_arch": [8] * 40}}, "at most 16 layer sizes"),
        # each layer within bounds, together gigabytes of weights (1.5 KB of JSON made torch reserve 7 GB)
        ({"policy_kwargs": {"net_arch": [4096] * 16, "n_critics": 10}}, "more than 33,554,432"),
        ({"policy_kwargs": {"net_arch": {"pi": [64], "qf": [4096] * 4}}}, "refused before building them"),
        ({"policy_kwargs": {"net_arch": {"pi": [64], "qf": [1], "vf": [4096] * 16}}}, "refused before building them"),  # PPO's
        ({"policy_kwargs": {"net_arch": [8], "activation_fn": "os.system"}}, "policy_kwargs must be an object with keys among"),
        ({"env_steps": -5}, r"env_steps must be an int in \[0, inf\]"),
        ({"goal_scaling": None}, "lacks or mangles a setting"),
        ({"config": {"agent": "sac", "camera_resolution": [10**6, 10**6]}}, "camera_resolution"),
    ],
)
def test_agent_settings_out_of_bounds_are_refused_before_a_network_is_built(tmp_path, settings, message):
    from dvrk_gym.baselines.checkpoints import load_agent

    text = _bounded(load_agent, _agent_files(tmp_path, {"policy.pth": b""}, **settings))
    assert pytest.importorskip("re").search(message, text), text


def test_agent_settings_that_are_not_json_or_too_large_are_refused(tmp_path):
    from dvrk_gym.baselines.checkpoints import load_agent

    path = _agent_files(tmp_path, {"policy.pth": b""})
    (tmp_path / "model.json").write_text('{"format": "dvrk_gym.baselines/1", "config": {')  # cut short
    assert "is not valid JSON" in _bounded(load_agent, path)
    (tmp_path / "model.json").write_text(" " * (2**20 + 1))
    assert "a JSON file read here has at most 1,048,576" in _bounded(load_agent, path)


def test_agent_weights_that_inflate_beyond_the_limit_or_hold_objects_are_refused(tmp_path):
    import torch

    from dvrk_gym.baselines.checkpoints import load_agent

    path = tmp_path / "model.zip"
    _agent_files(tmp_path, {})
    _deflated_zeros(path, "policy.pth", 5 * 64 * 2**20)
    assert "inflates to 335,544,320 bytes" in _bounded(load_agent, path)
    stream = io.BytesIO()
    torch.save({"weights": torch.zeros(2), "note": Path("x")}, stream)  # an object only a full unpickler would rebuild
    _agent_files(tmp_path, {"policy.pth": stream.getvalue()})
    text = _bounded(load_agent, path)
    assert "is not a plain tensor state dict (it holds objects other than tensors); refused, never unpickled" in text
    assert "weights_only" not in text  # torch's advice would be to run the file's code


def test_training_settings_refuse_a_network_no_agent_file_may_hold_before_training():
    """They trained in full and were refused at the save."""
    from dvrk_gym.baselines.training import TrainConfig

    with pytest.raises(ValueError, match="refused before building them"):
        TrainConfig(agent="sac", overrides={"policy_kwargs": {"net_arch": [4096] * 3}})
    with pytest.raises(ValueError, match="policy_kwargs must be an object with keys among"):
        TrainConfig(agent="sac", overrides={"policy_kwargs": {"net_arch": [64], "activation_fn": "os.system"}})
    assert TrainConfig(agent="sac", overrides={"policy_kwargs": {"net_arch": [256, 256], "n_critics": 2}}).agent == "sac"
