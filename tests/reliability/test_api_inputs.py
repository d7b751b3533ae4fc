"""The library's own functions given nonsense (from a review's probes): each refused with a
ValueError naming what is wrong, never a silent NaN, a silent coercion or a raw traceback."""

import csv
import http.server
import io
import json
import os
import signal
import socket
import threading
import time
import zipfile

import numpy as np
import pytest

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.features import check_inputs
from dvrk_gym.calibration.models.forests import ResidualForests
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.pipeline import PipelineConfig
from dvrk_gym.calibration.policy import CalibratedPolicy, calibrator_input
from dvrk_gym.sweep.grid import SweepSettings
from dvrk_gym.sweep.table import COLUMNS, write_csv
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, open_archive, read_member
from dvrk_gym.utils.checks import check_float


def _rows(n: int = 40, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = np.hstack([rng.uniform(-0.03, 0.03, (n, 3)) + [0.0, 0.0, 0.18], np.zeros((n, 1)), rng.uniform(-0.1, 0.1, (n, 2))])
    return X, X[:, :3] * [1.0, -1.0, -1.0] + [0.05, 0.05, 0.05]


def _encrypted_flag(data: bytes) -> bytes:
    """The zip with every member marked encrypted in the central directory (one bit each)."""
    array = bytearray(data)
    start = 0
    while (found := array.find(b"PK\x01\x02", start)) != -1:
        array[found + 8] |= 0x1
        start = found + 4
    return bytes(array)


def test_a_member_marked_encrypted_is_refused_naming_it(tmp_path):
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("params.json", "{}")
    path = tmp_path / "model.zip"
    path.write_bytes(_encrypted_flag(buffer.getvalue()))
    with pytest.raises(ArchiveLimitError, match="'params.json' is marked encrypted"):
        open_archive(path)
    rbt = tmp_path / "rbt.zip"
    RigidBodyCalibrator().fit(*_rows()).save(rbt)
    rbt.write_bytes(_encrypted_flag(rbt.read_bytes()))
    with pytest.raises(ValueError, match="marked encrypted"):
        RigidBodyCalibrator.load(rbt)
    with zipfile.ZipFile(buffer) as archive:  # the read itself, past an archive opened some other way
        archive.infolist()[0].flag_bits |= 0x1
        with pytest.raises(ArchiveLimitError, match="corrupt"):
            read_member(archive, "params.json")


@pytest.mark.parametrize(
    ("point", "yaw"),
    [([0.0, 0.0, 0.18], np.nan), ([0.0, 0.0, 0.18], np.inf), ([0.0, np.nan, 0.18], 0.0), ([0.0, 0.18], 0.0), (["0", "0", "0.18"], 0.0)],
)
def test_a_target_that_is_not_finite_is_refused_not_rounded_to_a_yaw(point, yaw):
    with pytest.raises(ValueError, match="finite"):
        calibrator_input(point, yaw)


def test_the_policy_refuses_an_observation_with_a_nan_yaw():
    policy = CalibratedPolicy(RigidBodyCalibrator().fit(*_rows()))
    observation = {"desired_goal": np.array([0.0, 0.0, 0.18], np.float32), "observation": np.array([0.0, 0.0, np.nan], np.float32)}
    with pytest.raises(ValueError, match="yaw must be a finite real number"):
        policy(observation)


def test_the_policy_refuses_a_calibrator_answering_in_millimetres_and_a_round_yaw_that_is_not_a_bool():
    """The env clamped 100 mm into its workspace and scored the touch 75 mm off, with no word."""

    class Millimetres:
        def predict(self, X):
            return np.array([[10.0, 20.0, -150.0]])

    observation = {"desired_goal": np.array([0.0, 0.0, 0.18], np.float32), "observation": np.array([0.0, 0.0, 0.0], np.float32)}
    with pytest.raises(ValueError, match=r"Millimetres\.predict\(X\)'s positions reach 150; expected metres"):
        CalibratedPolicy(Millimetres())(observation)
    with pytest.raises(ValueError, match="round_yaw must be True or False"):
        CalibratedPolicy(Millimetres(), round_yaw="no")


@pytest.mark.parametrize("groups", [[0.0, 1.0], [True], [0, 0], [5], "01"])
def test_residual_forest_groups_must_be_distinct_indices(groups):
    with pytest.raises(ValueError, match="groups"):
        ResidualForests._from_params({"trees": 2, "max_depth": None, "seed": 0, "groups": groups})


@pytest.mark.parametrize(("X", "dtype"), [(_rows()[0] + 0j, "complex128"), (_rows()[0] > 0, "bool"), (_rows()[0].astype(str), "<U")])
def test_model_inputs_of_other_kinds_are_not_coerced(X, dtype):
    with pytest.raises(ValueError, match=f"X must hold real numbers, got dtype {dtype}"):
        check_inputs(X)
    with pytest.raises(ValueError, match="real numbers"):
        RigidBodyCalibrator().fit(X, _rows()[1])


def test_the_dnn_refuses_what_overflows_it_instead_of_predicting_nan():
    X, y = _rows()
    with pytest.raises(ValueError, match="y's positions reach .*expected metres"):  # before it could overflow the scaling
        DNNCalibrator(epochs=1, progress=False).fit(X, y * 1e300)
    dnn = DNNCalibrator(epochs=1, progress=False).fit(X, y)
    far = X[:1].copy()
    far[0, 0] = 1e300
    with pytest.raises(ValueError, match="X.s positions reach 1e\\+300; expected metres"):  # it gave NaN, then no finite prediction
        dnn.predict(far)
    narrow = X.copy()
    narrow[:, 0] = 1e-44 * np.arange(len(X))  # a spread of about 1e-42 m: 1 mm away is beyond float32
    tight = DNNCalibrator(epochs=1, progress=False).fit(narrow, y)
    with pytest.raises(ValueError, match="X row 0 .* gives no finite prediction"):
        tight.predict(narrow[:1] + [1e-3, 0, 0, 0, 0, 0])
    assert np.isfinite(dnn.predict(X)).all()


def test_a_huge_int_is_refused_as_a_float_clearly():
    with pytest.raises(ValueError, match="x must be a finite number in \\[-1, 1\\], got a number too large for a float"):
        check_float("x", 10**400, low=-1, high=1)


@pytest.mark.parametrize("seeds", [range(40_000), range(3 * 10**9), 5])
def test_sweep_settings_refuse_a_huge_or_odd_grid_at_once(seeds):
    with pytest.raises(ValueError, match="bias_seeds"):
        SweepSettings(bias_seeds=seeds)


def test_a_sweep_table_with_a_bad_row_leaves_the_old_one(tmp_path):
    row = dict.fromkeys(COLUMNS, 1)
    path = write_csv([row, row], tmp_path / "sweep.csv")
    before = path.read_bytes()
    with pytest.raises(ValueError):
        write_csv([row, {**row, "extra": 1}], path)
    assert path.read_bytes() == before and len(list(csv.reader(io.StringIO(before.decode())))) == 3


@pytest.mark.parametrize("settings", [{"foo": 1}, {"camera_resolution": 5}, {"epochs": -1}])
def test_bad_calibration_settings_name_where_they_came_from(settings):
    with pytest.raises(ValueError, match="runs/cal/pipeline_config.json are not a calibration's settings"):
        PipelineConfig.from_settings(settings, source="runs/cal/pipeline_config.json")


@pytest.mark.parametrize("counts", [np.zeros(11), np.full(11, np.nan), -np.ones(11), np.ones((2, 11)), np.ones(5), np.ones(20)])
def test_the_detector_noise_fit_refuses_a_histogram_it_cannot_fit(counts):
    from dvrk_gym.fidelity.detector_noise import fit_detector_noise, held_out_pvalue
    from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE

    with pytest.raises(ValueError, match="counts must be a histogram of 11"):
        fit_detector_noise(counts)
    with pytest.raises(ValueError, match="counts must be a histogram of 11"):
        held_out_pvalue(IDENTIFIED_MARKER_NOISE, counts)


@pytest.mark.parametrize("max_px", [0, 11, 20, 2.5])
def test_the_held_out_test_refuses_a_pooling_point_beyond_the_histogram(max_px):
    from dvrk_gym.fidelity.detector_noise import held_out_pvalue
    from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE

    with pytest.raises(ValueError, match="max_px"):
        held_out_pvalue(IDENTIFIED_MARKER_NOISE, np.ones(11), max_px=max_px)


@pytest.mark.parametrize(
    ("keywords", "name"),
    [
        ({"replicates": 2.5}, "replicates"),
        ({"block": 0}, "block"),
        ({"block": -5}, "block"),
        ({"block": 80}, "block"),
        ({"seed": -1}, "seed"),
    ],
)
def test_the_bootstrap_refuses_blocks_and_replicates_it_cannot_draw(keywords, name):
    from dvrk_gym.fidelity.identify import InstrumentFit, bootstrap_sd
    from dvrk_gym.fidelity.instrument_model import initial_vector

    fit = InstrumentFit(initial_vector(np.eye(4)), np.ones(3), (0,))
    arguments = {"replicates": 2, "seed": 0, "block": 10} | keywords
    with pytest.raises(ValueError, match=name):
        bootstrap_sd(fit, np.zeros((60, 6)), np.zeros((60, 3)), **arguments)


@pytest.mark.parametrize("lags", [(), (0.3, 0.2), (0.2, 0.2), (0.5, 1.0), (-0.1, 0.2), (0.1, float("nan"))])
def test_the_settle_lag_match_refuses_its_grid_before_it_collects(lags, monkeypatch):
    from dvrk_gym.fidelity import settle_lag

    def collect(*args, **kwargs):
        raise AssertionError("collected a Phase I for a grid it refuses")

    monkeypatch.setattr(settle_lag, "run_paper_phase1", collect)
    with pytest.raises(ValueError, match="lag"):
        settle_lag.match_settle_lag(lags=lags, n_trajectories=1)


@pytest.mark.parametrize("methods", [("RBT", "RBT"), ("DNN", "DNN+RF", "DNN"), (), ("rbt",)])
def test_the_contact_fit_counts_each_method_once(methods):
    from dvrk_gym.calibration.datasets import load_paper_table_runs
    from dvrk_gym.fidelity.contact import fit_contact

    with pytest.raises(ValueError, match="each once"):
        fit_contact(load_paper_table_runs(), methods)


def test_fidelity_helpers_name_their_bad_counts():
    from dvrk_gym.fidelity.identify import split
    from dvrk_gym.fidelity.statistics import fidelity_statistics

    with pytest.raises(ValueError, match="n_rows"):
        split(10.6)
    X, y = _rows()
    with pytest.raises(ValueError, match="folds"):
        fidelity_statistics(X, y, folds="10")


@pytest.mark.parametrize(
    ("kind", "params"), [("linear", {"angles": "euler", "extra": 1}), ("forest", {"trees": 2, "max_depth": None, "seed": 0, "x": 1})]
)
def test_model_parameters_with_an_unknown_entry_are_refused(kind, params):
    from dvrk_gym.calibration.models.forests import ForestCalibrator
    from dvrk_gym.calibration.models.linear import LinearCalibrator

    with pytest.raises(ValueError, match="unexpected \\['(extra|x)'\\]"):
        {"linear": LinearCalibrator, "forest": ForestCalibrator}[kind]._from_params(params)


@pytest.mark.parametrize(
    ("keywords", "name"), [({"step_m": np.inf}, "step_m"), ({"step_m": 0.0}, "step_m"), ({"rotations_per_pause": 2.7}, "rotations")]
)
def test_the_exploration_policy_refuses_steps_it_cannot_take(keywords, name):
    from dvrk_gym.calibration.phase1 import PaperExplorationPolicy

    with pytest.raises(ValueError, match=name):
        PaperExplorationPolicy(seed=0, **keywords)


def test_a_folder_where_a_zip_should_be_is_named_as_a_folder(tmp_path):
    (tmp_path / "rbt.zip").mkdir()
    with pytest.raises(ArchiveLimitError, match="rbt.zip is a folder, not a zip archive"):
        open_archive(tmp_path / "rbt.zip")
    with pytest.raises(FileNotFoundError, match="no such file"):
        open_archive(tmp_path / "absent.zip")


def test_a_refused_dnn_fit_leaves_the_fitted_model_as_it_was():
    X, y = _rows()
    dnn = DNNCalibrator(epochs=1, progress=False).fit(X, y)
    before = dnn.predict(X)
    with pytest.raises(ValueError, match="y's positions reach"):
        dnn.fit(X, y * 1e300)
    assert np.array_equal(dnn.predict(X), before)


def test_residual_forests_refuse_yaws_of_other_kinds():
    with pytest.raises(ValueError, match="yaw must hold real numbers"):
        ResidualForests._check(np.zeros((2, 3)), np.array([True, False]))


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("debridement_picks", 65, "debridement_picks"),
        ("rl_eval_points", 20_000, "rl_eval_points"),
        ("rl_agents", ["sac", "sac"], "repeats"),
    ],
)
def test_a_profile_is_refused_with_values_its_tasks_would_refuse_later(field, value, message):
    """A run folder is stamped with its profile: refused only when its task ran, the corrected
    profile could not resume the folder."""
    from dvrk_gym.reproduce.profiles import MAX_EVAL_POINTS, TINY, Profile

    with pytest.raises(ValueError, match=message):
        Profile.from_dict({**TINY.to_dict(), field: value})
    from dvrk_gym.baselines.training import TrainConfig

    TrainConfig(agent="sac", steps=10, eval_points=MAX_EVAL_POINTS)
    with pytest.raises(ValueError, match="eval_points"):
        TrainConfig(agent="sac", steps=10, eval_points=MAX_EVAL_POINTS + 1)


def test_task_names_are_file_stems_and_a_result_that_is_not_json_is_a_task_error(tmp_path):
    from dvrk_gym.parallel.task_graph import Task, TaskError, run_tasks

    for name in ("../escaped", "sub/x", ".hidden", ""):
        with pytest.raises(ValueError, match="task name"):
            run_tasks([Task(name, dict)], cache_dir=tmp_path / "cache", workers=1)
    with pytest.raises(TaskError, match="cannot be saved as JSON"):
        run_tasks([Task("bad", _not_json)], cache_dir=tmp_path / "cache", workers=1)
    assert not (tmp_path / "escaped.json").exists()


def _not_json() -> dict:
    return {"value": object()}


def test_a_scheduler_address_the_options_cannot_reach_is_refused_up_front():
    pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    with pytest.raises(ValueError, match="give a tcp:// address"):
        DaskExecutor("tls://127.0.0.1:9")
    with pytest.raises(ValueError, match="connect_timeout_s"):
        DaskExecutor("tcp://127.0.0.1:9", connect_timeout_s=float("nan"))


@pytest.mark.parametrize("name", ["../../x", "a b/c", ".hidden", "", 3])
def test_a_profile_name_that_is_not_a_file_stem_is_refused(name, tmp_path, capsys, monkeypatch):
    """The name makes the run folder dvrk_gym_out/reproduce-<name>: "../../x" put the run
    outside dvrk_gym_out and left an empty folder behind."""
    from dvrk_gym.cli.main import main
    from dvrk_gym.reproduce.profiles import Profile

    with pytest.raises(ValueError, match="must be letters, digits"):
        Profile.from_dict({"name": name})
    (tmp_path / "profile.json").write_text(json.dumps({"name": name}))
    out = tmp_path / "work"
    out.mkdir()
    monkeypatch.chdir(out)
    assert main(["reproduce", "--profile", str(tmp_path / "profile.json"), "--workers", "1"]) == 2
    assert "must be letters, digits" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["profile.json", "work"] and not any(out.iterdir())


def test_a_profile_with_agents_that_are_not_names_is_a_clear_error():
    from dvrk_gym.reproduce.profiles import Profile

    with pytest.raises(ValueError, match="rl_agents must be a list of agent names"):
        Profile.from_dict({"name": "x", "rl_agents": [["sac"]]})


@pytest.mark.parametrize("calibrators", ["rbt", [], ()])
def test_the_calibrators_debridement_rows_want_a_list_of_names(calibrators, tmp_path):
    from dvrk_gym.baselines.comparison import calibration_debridement_rows

    with pytest.raises(ValueError, match="calibrators must be a list"):  # "rbt" was the letters r, b, t
        calibration_debridement_rows(tmp_path, calibrators=calibrators)


@pytest.mark.parametrize(
    ("keywords", "name"), [({"n_episodes": 1.5}, "n_episodes"), ({"n_episodes": 0}, "n_episodes"), ({"seed": -1}, "seed")]
)
def test_episodes_are_counted_in_whole_numbers_before_any_runs(keywords, name):
    from dvrk_gym.evaluation.episodes import run_episodes

    arguments = {"n_episodes": 2, "seed": 0} | keywords
    with pytest.raises(ValueError, match=name):
        run_episodes(None, lambda observation: None, **arguments)


def test_an_agent_row_of_no_benchmark_is_refused(tmp_path):
    from dvrk_gym.baselines.checkpoints import LoadedAgent
    from dvrk_gym.baselines.comparison import agent_row
    from dvrk_gym.baselines.training import TrainConfig

    agent = LoadedAgent(model=None, config=TrainConfig(agent="sac", steps=10), env_steps=10, path=tmp_path / "a.zip")
    with pytest.raises(ValueError, match="no benchmark settings"):
        agent_row(agent, {})


@pytest.mark.parametrize(("keywords", "name"), [({"max_folds": 0}, "max_folds"), ({"folds": 1}, "folds"), ({"folds": 10**6}, "folds")])
def test_a_cross_validation_that_would_score_no_fold_is_refused(keywords, name):
    from dvrk_gym.calibration.models.linear import LinearCalibrator
    from dvrk_gym.calibration.search import cross_validate

    X, y = _rows()
    with pytest.raises(ValueError, match=name):  # max_folds=0 gave a NaN error
        cross_validate(lambda seed: LinearCalibrator(), X, y, **keywords)


def test_the_default_calibrated_target_names_the_env_it_reads():
    from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
    from dvrk_gym.calibration.policy import CalibratedPolicy

    policy = CalibratedPolicy(RigidBodyCalibrator().fit(*_rows()))
    with pytest.raises(ValueError, match="target=fragment_target"):  # was a bare KeyError 'desired_goal'
        policy({"fragment_positions": np.zeros((8, 3)), "fragment_seen": np.ones(8)})


def test_a_dask_worker_running_other_dvrk_gym_source_refuses_the_call_before_running_it(tmp_path):
    """Sweep units and reproduce stages on a worker with another commit would have mixed two
    simulators' numbers in one folder, unchecked."""
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor, WorkerSourceError

    marker = tmp_path / "ran"
    with (
        distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster,
        DaskExecutor(cluster.scheduler_address) as dask,
    ):
        assert dask.submit(divmod, 7, 2).result(timeout=60) == (3, 1)  # the same source: runs
        dask._source = "0" * 64  # as a worker of another commit would compare
        future = dask.submit(marker.write_text, "x")
        with pytest.raises(WorkerSourceError, match=r"runs dvrk_gym .* source sha256 000000000000: install the same commit"):
            future.result(timeout=60)
    assert not marker.exists()


def test_a_cluster_with_a_worker_of_other_dvrk_gym_source_is_refused_at_connect_naming_it(monkeypatch):
    """Checked only by each call, such a worker refused its calls in a moment and so was
    given the next at once: one of two workers failed 9 units of a sweep of 10."""
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel import dask_executor

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        with dask_executor.DaskExecutor(cluster.scheduler_address) as dask:  # the same source everywhere: taken
            assert dask.submit(divmod, 7, 2).result(timeout=60) == (3, 1)
        monkeypatch.setattr(dask_executor, "worker_source_sha256", lambda: "0" * 64)  # as workers of another commit answer
        with pytest.raises(
            ValueError, match=r"2 of 2 Dask workers do not run this dvrk_gym source .*inproc://.*: source sha256 000000000000"
        ):
            dask_executor.DaskExecutor(cluster.scheduler_address)

        def broken() -> str:
            raise ModuleNotFoundError("No module named 'dvrk_gym'")

        monkeypatch.setattr(dask_executor, "worker_source_sha256", broken)  # as a worker without the package answers
        with pytest.raises(ValueError, match=r"inproc://.*: cannot say which it runs \(.*No module named 'dvrk_gym'"):
            dask_executor.DaskExecutor(cluster.scheduler_address)
        assert len(cluster.scheduler.clients) == 1  # the refused clients were closed (the cluster's own is left)


def test_a_stopped_dask_worker_does_not_hang_the_connect_check(caplog):
    """Client.run waits for every worker without a time limit: one worker stopped with
    SIGSTOP held the connect for good (still waiting after 165 s)."""
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        with distributed.Client(cluster.scheduler_address) as probe:
            (worker_pid,) = probe.run(os.getpid).values()
        os.kill(worker_pid, signal.SIGSTOP)
        try:
            began = time.monotonic()
            with DaskExecutor(cluster.scheduler_address, connect_timeout_s=2.0) as dask:
                took_s = time.monotonic() - began
                assert dask.description.startswith("Dask scheduler")
        finally:
            os.kill(worker_pid, signal.SIGCONT)
    assert took_s < 30.0
    assert "could not ask every Dask worker within 2 s which dvrk_gym it runs" in caplog.text


def test_a_port_that_sends_bytes_of_another_protocol_is_refused_saying_so_not_with_a_memory_error():
    """Its first bytes, read as the length of Dask's first message, made the refusal say
    "MemoryError: Unable to allocate 2.64 EiB"."""
    pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    with socket.create_server(("127.0.0.1", 0)) as server:
        accepted = []

        def babble() -> None:
            connection, _ = server.accept()
            accepted.append(connection)  # kept open until the test ends
            connection.sendall(b"\x2a" * 64)

        threading.Thread(target=babble, daemon=True).start()
        with pytest.raises(ValueError, match="what answered does not speak Dask's protocol"):
            DaskExecutor(f"tcp://127.0.0.1:{server.getsockname()[1]}", connect_timeout_s=3.0)
        for connection in accepted:
            connection.close()


def test_a_port_that_is_no_scheduler_is_refused_in_about_the_connect_timeout():
    """A port that takes the connection but speaks HTTP (a scheduler's dashboard: 8787 for
    8786) never answers Dask's handshake: the client waited for ever, whatever the timeout."""
    pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    with http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler) as server:
        threading.Thread(target=server.serve_forever, daemon=True).start()
        errors: list[BaseException] = []

        def connect() -> None:
            try:
                DaskExecutor(f"tcp://127.0.0.1:{server.server_address[1]}", connect_timeout_s=1.0)
            except BaseException as error:  # noqa: BLE001
                errors.append(error)

        attempt = threading.Thread(target=connect, daemon=True)
        attempt.start()
        attempt.join(120)  # a bound for the test only: it hung for ever
        server.shutdown()
    assert not attempt.is_alive()
    assert len(errors) == 1 and isinstance(errors[0], ValueError)
    assert "what answered there is no Dask scheduler" in str(errors[0])
