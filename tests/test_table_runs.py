"""The authors' records of their calibration table's runs: converted without unpickling, loaded
as documented, and compared with the simulated robot by benchmarks/fidelity_table_runs.py."""

import argparse
import dataclasses
import io
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from benchmark_scripts import ROOT, load_script, script_path

from dvrk_gym import paper
from dvrk_gym.calibration import datasets
from dvrk_gym.calibration.datasets import load_paper_phase1, load_paper_table_runs
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.pipeline import SETTINGS_STAMP, PipelineConfig
from dvrk_gym.evaluation.table_protocol import RAW
from dvrk_gym.utils.run_folder import RunFolder

convert = load_script("convert_authors_table_runs")
table_runs = load_script("fidelity_table_runs")

AUTHORS_RIGID_BODIES = {  # config/mapping_results/auto_params_matrices_v01.txt of the authors' code (MIT)
    -90: [
        [-0.98469948, -0.11571814, -0.13029293, 0.05728807],
        [-0.10775915, 0.99194472, -0.0665855, 0.06863919],
        [0.13694853, -0.05152645, -0.98923714, 0.01830053],
    ],
    -45: [
        [-0.96595194, -0.13894361, -0.21824646, 0.07288824],
        [-0.09884257, 0.97775511, -0.18500025, 0.08997862],
        [0.2390962, -0.15712931, -0.95819799, 0.00893222],
    ],
    0: [
        [-0.96495117, -0.15152931, -0.21426179, 0.07144416],
        [-0.12126445, 0.98152178, -0.14802005, 0.08252093],
        [0.23273199, -0.11684978, -0.9654957, 0.01069401],
    ],
    45: [
        [-0.94497925, -0.17421353, -0.27688239, 0.08259128],
        [-0.1168754, 0.97033351, -0.21164362, 0.09437622],
        [0.30553944, -0.16763808, -0.93730631, 0.00602642],
    ],
    90: [
        [-0.96027262, -0.12511899, -0.24944285, 0.07913463],
        [-0.13012384, 0.99149118, 0.00360796, 0.05410029],
        [0.24686896, 0.03592309, -0.9683828, 0.01656888],
    ],
}


def _escaped(raw: bytes) -> str:
    return "".join(f"\\x{b:02x}" for b in raw)


def _record(x: float, array: np.ndarray, frame: np.ndarray) -> bytes:
    """One record in the authors' format: a list of floats, a numpy array, a tfx frame (an ndarray
    subclass with its own state), a tuple of ints."""
    text = (
        "(dp0\nS'actual_pos'\np1\n(lp2\nFX_VALUE\naF0.5\naF-0.25\nas"
        "S'target_pos'\np3\ncnumpy.core.multiarray\n_reconstruct\np4\n(cnumpy\nndarray\np5\n(I0\ntp6\nS'b'\np7\ntp8\nRp9\n"
        "(I1\n(I3\ntp10\ncnumpy\ndtype\np11\n(S'f8'\np12\nI0\nI1\ntp13\nRp14\n(I3\nS'<'\np15\nNNNI-1\nI-1\nI0\ntp16\nbI00\nS'ARRAY_BYTES'\np17\ntp18\nbs"
        "S'frame'\np19\ng4\n(ctfx.canonical\nCanonicalTransform\np20\n(I0\ntp21\ng7\ntp22\nRp23\n((I1\n(I4\nI4\ntp24\ng14\nI00\nS'FRAME_BYTES'\np25\ntp26\n(I01\nNNNtp27\ntp28\nbs"
        "S'center_target_pixels'\np29\n(I730\nI121\ntp30\ns."
    )
    text = text.replace("X_VALUE", repr(x)).replace("ARRAY_BYTES", _escaped(array.astype("<f8").tobytes()))
    return text.replace("FRAME_BYTES", _escaped(frame.astype("<f8").tobytes()))


def test_the_reader_gives_back_what_the_authors_wrote_one_record_after_another():
    frame = np.arange(16.0).reshape(4, 4)
    data = (_record(0.125, np.array([0.07, 0.017, -0.1667]), frame) + _record(-1.5, np.array([1.0, 2.0, 3.0]), frame)).encode("latin-1")
    first, second = convert.read_protocol0_records(data)
    assert first["actual_pos"] == [0.125, 0.5, -0.25] and second["actual_pos"][0] == -1.5
    np.testing.assert_array_equal(first["target_pos"], [0.07, 0.017, -0.1667])
    np.testing.assert_array_equal(first["frame"], frame)
    assert first["center_target_pixels"] == (730, 121)
    np.testing.assert_array_equal(convert._position(first["frame"]), [3.0, 7.0, 11.0])  # a frame's translation column


def test_the_reader_never_calls_what_a_tampered_record_names(tmp_path):
    marker = tmp_path / "ran"
    hostile = f"cos\nsystem\n(S'touch {marker}'\ntR.".encode()
    with pytest.raises(ValueError, match="os.system"):
        convert.read_protocol0_records(hostile)
    assert not marker.exists()
    with pytest.raises(ValueError, match="opcode"):
        convert.read_protocol0_records(b"(dp0\n\x80\x02.")
    with pytest.raises(ValueError, match="protocol-0 records"):
        convert.read_protocol0_records(_record(0.1, np.zeros(3), np.eye(4)).encode("latin-1")[:-40])


def test_shared_objects_stay_shared_and_nesting_is_bounded():
    doubling = b"(lp0\n" + b"(g0\ng0\nlp0\n" * 200 + b"."  # each list holds the previous one twice: 2**200 leaves if copied
    (record,) = convert.read_protocol0_records(doubling)
    assert record[0] is record[1] and record[0][0] is record[0][1]
    (itself,) = convert.read_protocol0_records(b"(dp0\nS'a'\ng0\ns.")
    assert itself["a"] is itself
    with pytest.raises(ValueError, match="nests deeper"):
        convert.read_protocol0_records(b"(" * (convert.MAX_NESTING + 1) + b".")


def test_a_record_file_too_large_is_refused_before_reading(tmp_path):
    path = tmp_path / "data_v42.p"
    path.write_bytes(b"(" * (convert.MAX_FILE_BYTES + 1))
    with pytest.raises(ValueError, match="bytes"):
        convert._read(path)


def test_the_packaged_runs_are_the_papers_table_and_its_protocol():
    runs = load_paper_table_runs()
    for label, cells in paper.CALIBRATION_PIXELS.items():
        for setting, cell in enumerate(cells):
            mine = (runs.method == label) & (runs.setting == setting)
            assert mine.sum() == paper.GRID_CIRCLES
            assert abs(runs.pixel_error[mine].mean() - cell) < 0.1, (label, setting)  # the paper truncates its cells
            lift = 1e-3 * paper.TABLE_LIFT_MM[label][setting]
            heights = runs.sent[mine, 2] - lift  # the prediction, clipped where the run clipped
            inside = (paper.TABLE_Z_BAND_M[0] - 1e-9 <= heights) & (heights <= paper.TABLE_Z_BAND_M[1] + 1e-9)
            assert inside.all() == paper.TABLE_CLIPPED[label][setting], (label, setting)
            if setting < 5:  # the fixed yaws, with the paper's pitch and roll
                yaw = paper.PHASE2_YAWS_DEG[setting]
                pitch = np.interp(yaw, [-90, 90], paper.PITCH_AT_YAW_EXTREMES_DEG)
                roll = np.interp(yaw, [-90, 90], paper.ROLL_AT_YAW_EXTREMES_DEG)
                np.testing.assert_allclose(np.rad2deg(runs.sent_rotation[mine]), np.tile([yaw, pitch, roll], (35, 1)), atol=1e-9)
    assert np.bincount(runs.push_round).tolist() == [175, 175]
    assert sorted(set(np.rad2deg(runs.push_yaw).round(6))) == list(paper.PHASE2_YAWS_DEG)
    assert np.abs(runs.push_after - runs.push_before).max() < 0.01  # a push moves the jaws millimetres


def _repacked(read, change):
    """A ``_read_packaged`` that gives the packaged npz with ``change(arrays)`` applied."""

    def read_changed(folder, name):
        with np.load(io.BytesIO(read(folder, name)), allow_pickle=False) as data:
            arrays = {key: data[key].copy() for key in data.files}
        change(arrays)
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        return buffer.getvalue()

    return read_changed


def test_a_damaged_package_file_is_refused(monkeypatch):
    real = datasets._read_packaged
    monkeypatch.setattr(datasets, "_read_packaged", _repacked(real, lambda arrays: arrays.pop("push_round")))
    with pytest.raises(ValueError, match="push_round"):
        load_paper_table_runs()

    def stray_method_and_nan(arrays):
        arrays["touch_method"][7] = "LSTM"
        arrays["push_after_m"][3, 2] = np.nan

    monkeypatch.setattr(datasets, "_read_packaged", _repacked(real, stray_method_and_nan))
    with pytest.raises(ValueError, match="LSTM.*non-finite \\['push_after_m'\\]"):
        load_paper_table_runs()


def test_the_packages_rigid_body_on_the_real_rows_is_the_one_the_table_used():
    X, y = load_paper_phase1()
    rbt = RigidBodyCalibrator().fit(X, y)
    runs = load_paper_table_runs()
    for setting, yaw in enumerate(paper.PHASE2_YAWS_DEG):
        matrix = np.array(AUTHORS_RIGID_BODIES[int(yaw)])
        mine = (runs.method == "RBT") & (runs.setting == setting)
        clipped = runs.sent[mine] - [0.0, 0.0, 1e-3 * paper.TABLE_LIFT_MM["RBT"][setting]]
        free = ~paper.TABLE_CLIPPED["RBT"][setting] | (
            (clipped[:, 2] > paper.TABLE_Z_BAND_M[0] + 1e-9) & (clipped[:, 2] < paper.TABLE_Z_BAND_M[1] - 1e-9)
        )
        camera = (clipped[free] - matrix[:, 3]) @ matrix[:, :3]  # the circles' camera positions of that run
        inputs = np.c_[camera, runs.sent_rotation[mine][free]]
        np.testing.assert_allclose(rbt.predict(inputs), clipped[free], atol=2e-6)  # metres


def test_a_setting_without_pushes_has_no_heights():
    points = np.array([[0.005, 0.005, -0.1], [0.02, 0.0, -0.105]])
    stats = table_runs.statistics(np.array([10.0, 20.0]), points, points + [0, 0, 0.001], None)
    assert stats[0] == 15.0 and np.isnan(stats[1:]).all()


def test_phase1_rows_are_measured_over_the_plane_of_their_nearest_yaw():
    yaws = np.deg2rad(paper.PHASE2_YAWS_DEG)
    grid = np.array([[x, y] for x in (0.0, 0.05) for y in (0.0, 0.05)])
    pushed = np.vstack([np.c_[grid, np.full(4, -0.16 + 0.001 * i)] for i in range(5)])  # a flat plane per yaw, 1 mm apart
    pushed_yaws = np.repeat(yaws, 4)
    rows = np.array([[0.01, 0.02, -0.155], [0.03, 0.01, -0.155]])
    heights = table_runs.rows_over_pushes(rows, np.deg2rad([-80.0, 50.0]), pushed, pushed_yaws)  # nearest: yaw -90, yaw 45
    np.testing.assert_allclose(heights, [0.005, 0.002], atol=1e-12)


def test_the_real_rigid_body_dove_under_the_paper_and_was_lifted_to_it():
    real = table_runs.real_table(load_paper_table_runs())
    predicted_over = np.array([cell[1] for cell in real["RBT"][:5]])
    sent_over = np.array([cell[2] for cell in real["RBT"][:5]])
    assert (predicted_over < -5.0).all()  # mm: what the authors' notes call the height problem
    assert (np.abs(sent_over) < 2.5).all()  # their lifts brought it back to about the paper
    network = np.array([cell[1] for cell in real["DNN"][:5]])
    assert (np.abs(network) < 2.0).all()


def test_it_prints_the_real_and_simulated_rows(small_calibration, tmp_path):
    result = subprocess.run(
        [sys.executable, str(script_path("fidelity_table_runs")), "--calibration", str(small_calibration)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    for label in paper.METHOD_LABELS.values():
        block = next(i for i, line in enumerate(lines) if line.startswith(f"{label} (lifts"))
        real_cells = [float(v) for v in lines[block + 1].split()[-7:-1]]
        assert real_cells == pytest.approx(paper.CALIBRATION_PIXELS[label], abs=0.11)
        simulated = [line for line in lines[block + 2 : block + 4] if line.split()[0] == "sim,"]
        assert len(simulated) == (2 if label == "RBT" else 1)  # the authors' way differs from raw for the rigid body only
        assert all(len(line.split()[-7:]) == 7 and min(float(v) for v in line.split()[-7:]) >= 0.0 for line in simulated)
    gave = lines.index(next(line for line in lines if line.startswith("RBT, the touches sent more than 1 mm under")))
    real_give = "real 73 touches sent 2.7 mm under, reported 1.1 mm over the sent height (0.42 of the depth)"
    assert " ".join(lines[gave + 1].split()) == real_give  # the authors' records, whatever the simulation
    assert [line.split()[1] for line in lines[gave + 2 : gave + 4]] == ["the", "raw"]  # the authors' way, raw
    heights = [line for line in lines if line.startswith("Phase I kept rows over the pushed jaws")]
    assert [line.split(",")[1].split(":")[0].strip() for line in heights] == ["real", "sim"]
    assert heights[0].endswith("-0.7 / 0.9 / 3.7 mm (5th / 50th / 95th percentile)")  # the authors' rows, their first round's pushes
    pushes = lines.index(next(line for line in lines if line.startswith("Phase II pushes: how far the person moved")))
    real_pushes = "real, round 0 +0.7, +1.8 -0.3, +2.3 -0.8, +1.8 -0.6, +1.3 +0.2, +1.3 1.0"
    assert " ".join(lines[pushes + 2].split()) == real_pushes  # the authors' pushes: y within 1 mm over the yaws
    real_second = "real, round 1 -0.2, +1.6 -1.3, +2.0 -1.3, +1.8 -0.7, +1.3 -0.0, +1.6 0.7"
    assert " ".join(lines[pushes + 3].split()) == real_second and lines[pushes + 4].split()[0] == "sim"
    assert len(lines[pushes + 4].split()) == 1 + 2 * 5 + 1
    missing = subprocess.run(
        [sys.executable, str(script_path("fidelity_table_runs")), "--calibration", str(Path(tmp_path))],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert missing.returncode == 2 and "not a calibration run folder" in missing.stderr


def test_read_calibration_gives_the_config_a_calibration_folder_was_stamped_with(tmp_path):
    config = PipelineConfig(n_trajectories=2, dnn_epochs=20, camera_resolution=(640, 360))
    with RunFolder(tmp_path, dataclasses.asdict(config), stamp=SETTINGS_STAMP):  # as run_calibration stamps it, fingerprint and all
        pass
    assert table_runs.read_calibration(argparse.ArgumentParser(), tmp_path) == config


def test_the_give_counts_the_deep_touches_and_their_reported_rise():
    pushed = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.1, 0.1, 0.0]])  # the plane z = 0
    sent = np.array([[0.05, 0.05, -0.003], [0.02, 0.03, -0.0005], [0.03, 0.02, 0.002], [0.04, 0.04, -0.005]])
    reported = sent + [[0.0, 0.0, 0.002], [0.0, 0.0, 0.0004], [0.0, 0.0, 0.0], [0.0, 0.0, 0.004]]
    n, depth, rise = table_runs.give([sent[:2], sent[2:]], [reported[:2], reported[2:]], [pushed, pushed])
    assert n == 2  # 3 and 5 mm under; 0.5 mm under is too shallow, 2 mm over does not count
    assert depth == pytest.approx(4.0) and rise == pytest.approx(3.0)  # medians, mm
    assert table_runs.give([sent[2:3]], [reported[2:3]], [pushed])[0] == 0


def test_the_push_means_are_taken_per_nearest_paper_yaw():
    yaws = np.deg2rad([-88.0, -92.0, -40.0, 3.0, 50.0, 85.0, 89.0])
    moves = np.array([[1.0, 0, 0], [3.0, 0, 0], [0, 2.0, 0], [0, 0, 4.0], [5.0, 5.0, 5.0], [0, 1.0, 0], [0, 3.0, 0]])
    means = table_runs.push_means(yaws, moves)
    np.testing.assert_allclose(means, [[2.0, 0, 0], [0, 2.0, 0], [0, 0, 4.0], [5.0, 5.0, 5.0], [0, 2.0, 0]])
    with pytest.raises(ValueError, match="every paper yaw needs a push"):
        table_runs.push_means(yaws[:-3], moves[:-3])  # none at yaw 45 or 90
    with pytest.raises(ValueError, match="every paper yaw needs a push"):
        table_runs.push_means(yaws, moves[:-1])


def test_the_simulated_passes_are_seeded_from_the_runs_seed(monkeypatch):
    seeds = []

    def fake_pass(env, touch, yaw, seed):  # one episode per circle, as touch_grid_episodes gives them (three circles here)
        seeds.append(seed)
        episodes = []
        for corner in ([0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]):  # pushes a plane can be fitted through
            touch(None)
            info = {"reported_position": np.array(corner), "human_correction": np.zeros(3)}
            episodes.append(SimpleNamespace(final_info=info, metrics={"pixel_error": 1.0}))
        return episodes

    monkeypatch.setattr(table_runs, "touch_grid_episodes", fake_pass)
    policy = lambda observation: np.array([0.04, 0.04, -0.16, 0.0], dtype=np.float32)  # noqa: E731
    protocol = (RAW,) * 6
    table_runs.simulated_touches(None, policy, protocol, seed=1007)  # a run made with --seed 7
    assert seeds == [1007, 1008, 1009, 1010, 1011, 1012]
    seeds.clear()
    table_runs.simulated_table(None, policy, protocol)
    assert seeds == [1000 + k for k in range(6)]  # dvrk-gym evaluate's seeds for a run made with --seed 0
