"""The command line's output problems: one line on stderr, exit status 2, nothing half written.

Each command is checked before it does any work: an ``--out`` naming a file or a folder that
cannot be written, a ``phase1.npz`` that ``collect`` would overwrite, a ``--calibration``
folder with no model, a bad profile, a run folder another process owns.
"""

import json
import os
import re
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from faults import ROOT, environment, files_in, run_cli

from dvrk_gym.cli.main import main


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder this process cannot write: /sys for root (which ignores permissions), else a mode 0o500 folder."""
    if os.geteuid() == 0:
        yield Path("/sys")
        return
    folder = tmp_path / "read_only"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    yield folder
    folder.chmod(stat.S_IRWXU)


def _fails_in_one_line(capsys, argv, *words):
    """``dvrk-gym ARGV`` returns 2 and prints one line naming ``words`` on stderr (and no traceback)."""
    status = main(argv)
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


COMMANDS = {
    "demo": ["demo", "--circles", "1"],
    "collect": ["collect", "--trajectories", "1"],
    "calibrate": ["calibrate", "--trajectories", "1"],
    "evaluate": ["evaluate", "--trajectories", "1"],
    "search": ["search", "--quick"],
    "debride": ["debride", "--calibrate"],
    "baseline train": ["baseline", "train", "--algo", "sac", "--steps", "10"],
    "baseline evaluate": ["baseline", "evaluate", "--model", "missing.zip"],
    "reproduce": ["reproduce", "--quick"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_out_naming_a_file_is_a_one_line_error(capsys, tmp_path, command):
    target = tmp_path / "results.txt"
    target.write_text("keep me")
    start = time.perf_counter()
    _fails_in_one_line(capsys, [*COMMANDS[command], "--out", str(target)], str(target), "is a file, not a folder")
    assert time.perf_counter() - start < 30.0  # refused before any work
    assert target.read_text() == "keep me" and files_in(tmp_path) == {"results.txt"}


@pytest.mark.parametrize("command", ["demo", "collect", "calibrate", "baseline train", "reproduce"])
def test_out_in_a_read_only_folder_is_a_one_line_error(capsys, read_only_folder, command):
    before = files_in(read_only_folder) if read_only_folder != Path("/sys") else None
    out = read_only_folder if command == "demo" else read_only_folder / "run"
    _fails_in_one_line(capsys, [*COMMANDS[command], "--out", str(out)], "cannot be written")
    if before is not None:
        assert files_in(read_only_folder) == before


def test_baseline_train_checks_its_folder_before_training(capsys, read_only_folder):
    start = time.perf_counter()
    _fails_in_one_line(capsys, ["baseline", "train", "--algo", "sac", "--steps", "200000", "--out", str(read_only_folder / "x")])
    assert time.perf_counter() - start < 30.0  # 200,000 steps would take hours


def test_collect_refuses_unstamped_phase1_and_loads_its_own_again_unless_forced(capsys, tmp_path):
    (tmp_path / "phase1.npz").write_bytes(b"the old data")  # of no recorded settings: refused, --force or not
    for force in ([], ["--force"]):
        _fails_in_one_line(capsys, ["collect", "--out", str(tmp_path), "--trajectories", "1", *force], "no settings stamp", "phase1.npz")
    assert (tmp_path / "phase1.npz").read_bytes() == b"the old data"
    stamped = tmp_path / "stamped"
    assert main(["collect", "--out", str(stamped), "--trajectories", "1", "--resolution", "320", "180", "--no-progress"]) == 0
    capsys.readouterr()
    first = (stamped / "phase1.npz").read_bytes()
    again = ["collect", "--out", str(stamped), "--trajectories", "1", "--resolution", "320", "180", "--no-progress"]
    assert main(again) == 0  # it refused a re-run ("phase1.npz exists; give --force"): a script re-run failed
    assert f"loaded {stamped / 'phase1.npz'}, made by an earlier run with these settings" in capsys.readouterr().out
    (stamped / "phase1.npz").write_bytes(first[: len(first) // 2])  # cut short: set aside and collected again
    assert main(again) == 0
    assert f"wrote {stamped / 'phase1.npz'}" in capsys.readouterr().out and (stamped / "phase1.npz").read_bytes() == first
    assert main([*again, "--force"]) == 0
    assert f"wrote {stamped / 'phase1.npz'}" in capsys.readouterr().out and (stamped / "phase1.npz").read_bytes() == first


@pytest.mark.parametrize("exists", [False, True], ids=["missing-folder", "folder-without-model"])
def test_debride_refuses_a_calibration_folder_without_a_model(capsys, tmp_path, exists):
    calibration = tmp_path / "calibraton"  # misspelt
    if exists:
        calibration.mkdir()
    start = time.perf_counter()
    word = "has no two_phase.zip" if exists else "does not exist"
    _fails_in_one_line(capsys, ["debride", "--calibration", str(calibration), "--out", str(tmp_path / "out")], word, "--calibrate")
    assert time.perf_counter() - start < 30.0 and not (tmp_path / "out").exists()
    assert files_in(calibration) == set()  # no calibration was started in it


def test_evaluate_refuses_a_policy_factory_that_does_not_take_the_env_in_one_line(capsys, tmp_path):
    _fails_in_one_line(
        capsys,
        ["evaluate", "--policy", "policies_for_tests:takes_nothing", "--episodes", "1", "--out", str(tmp_path), "--no-progress"],
        "must take the env as its one argument",
    )


def test_debride_given_a_reproduce_run_folder_points_at_its_calibration(capsys, tmp_path):
    (tmp_path / "calibration").mkdir()
    (tmp_path / "calibration" / "two_phase.zip").write_bytes(b"")  # only its presence is looked at before the refusal
    _fails_in_one_line(
        capsys,
        ["debride", "--calibration", str(tmp_path), "--out", str(tmp_path / "out")],
        f"its calibration is in {tmp_path / 'calibration'}",
    )


@pytest.mark.parametrize(
    ("profile", "words"),
    [
        ('{"name": "tiny", "n_trajectories": ', ("profile", "Expecting value")),
        ('{"name": "tiny", "trajectories": 2}', ("unknown profile field", "trajectories")),
        ('{"name": "tiny", "debridement_trials": "3"}', ("debridement_trials must be an int",)),
        ('{"name": "tiny", "camera_resolution": [10, 10]}', ("camera_resolution",)),
        ("[1, 2]", ("a profile must be a JSON object",)),
    ],
    ids=["cut-json", "unknown-field", "string-count", "tiny-camera", "not-an-object"],
)
def test_reproduce_refuses_a_bad_profile(capsys, tmp_path, profile, words):
    path = tmp_path / "profile.json"
    path.write_text(profile)
    _fails_in_one_line(capsys, ["reproduce", "--profile", str(path), "--out", str(tmp_path / "run")], *words)
    assert not (tmp_path / "run").exists()


def test_reproduce_refuses_quick_and_a_profile_together(capsys, tmp_path):
    (tmp_path / "p.json").write_text('{"name": "x"}')
    _fails_in_one_line(capsys, ["reproduce", "--quick", "--profile", str(tmp_path / "p.json"), "--out", str(tmp_path / "r")], "not both")


def test_reproduce_in_a_folder_another_run_owns_is_an_error_naming_its_pid(capsys, tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom dvrk_gym.utils.run_folder import RunFolder\nf = RunFolder(sys.argv[1])\n"
         "print('holding', flush=True)\ntime.sleep(600)\n", str(tmp_path / "run")],
        stdout=subprocess.PIPE, text=True, env=environment(), cwd=ROOT,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "holding"
        _fails_in_one_line(capsys, ["reproduce", "--quick", "--out", str(tmp_path / "run")], "in use by", f"process {holder.pid}")
    finally:
        holder.kill()
        holder.wait()
    assert sorted(files_in(tmp_path / "run")) == ["run.lock"]


def test_the_console_command_exits_2_with_one_line(tmp_path):
    """The real entry point in a fresh process: exit status 2, one line, no traceback."""
    (tmp_path / "out").write_text("a file")
    result = run_cli("demo", "--out", str(tmp_path / "out"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith("dvrk-gym demo: error:") and not any("Traceback" in line for line in lines), result.stderr


def test_evaluate_refuses_options_that_are_not_a_json_object(capsys, tmp_path):
    argv = ["evaluate", "--policy", "dvrk_gym.evaluation.episodes:as_policy", "--out", str(tmp_path / "out")]
    for options in ("{yaw: 0}", "[1]"):
        _fails_in_one_line(capsys, [*argv, "--options", options], "--options must be a JSON object")
    assert not (tmp_path / "out").exists()


REFUSED_BEFORE_ANY_WORK = [
    (["calibrate", "--epochs", "-1"], "--epochs"),
    (["collect", "--trajectories", "-3"], "--trajectories"),
    (["evaluate", "--trajectories", "0"], "--trajectories"),
    (["demo", "--circles", "0"], "--circles"),
    (["evaluate", "--env", "dvrk_gym/Nope-v0", "--policy", "os:getcwd"], "--env"),
    (["evaluate", "--env", "CartPole-v1", "--policy", "os:getcwd"], "--env"),
    (["evaluate", "--env", "dvrk_gym/GridTouch-v0", "--policy", "os:getcwd", "--episodes", "-1"], "--episodes"),
    (["search", "--folds", "1"], "--folds"),
    (["reproduce", "--workers", "-1"], "workers"),
    (["baseline", "evaluate", "--model", "missing.zip"], "missing.zip"),
    (["baseline", "train", "--learning-starts", "-1", "--steps", "10"], "--learning-starts"),
    (["demo", "--bias-seed", "-1"], "--bias-seed"),
    (["fidelity", "--resolution", "5", "5"], "--resolution"),
    (["debride", "--calibrate", "--bias-seed", "-1"], "--bias-seed"),
    (["baseline", "train", "--algo", "sac", "--n-envs", "0"], "--n-envs"),
    (["baseline", "train", "--algo", "sac", "--eval-points", "-1"], "--eval-points"),
    (["baseline", "train", "--algo", "sac", "--eval-points", "11", "--steps", "10"], "--eval-points 11 is more than the 10 env steps"),
    (["baseline", "train", "--algo", "sac", "--seed", "-1"], "--seed"),
    (["baseline", "train", "--algo", "sac", "--steps", "-1"], "--steps"),
    (["evaluate", "--episodes", "3"], "--policy only"),
    (["evaluate", "--env", "dvrk_gym/GridTouch-v0", "--options", "{}"], "--env and --options apply to --policy only"),
    (["evaluate", "--policy", "os:getcwd", "--env", ""], "--env"),
    (["evaluate", "--policy", "os:getcwd", "--epochs", "5"], "--epochs set the calibration's budget"),
    (["sweep", "--epochs", "0"], "--epochs"),
    (["sweep", "--trajectories", "0"], "--trajectories"),
    (["reproduce", "--seed", "-1"], "--seed"),
    (["fidelity", "--trajectories", "0"], "--trajectories"),
    (["fidelity", "--seed", "-1"], "--seed"),
    (["fidelity", "--bootstrap", "1"], "--bootstrap"),
    (["debride", "--calibrate", "--seed", "-1"], "--seed"),
    (["sweep", "--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", "nan"], "--connect-timeout"),
    (["reproduce", "--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", "-1"], "--connect-timeout"),
    (["reproduce", "--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", "1e7"], "--connect-timeout"),
    (["debride", "--calibrate", "--trials", "1000000000"], "--trials"),
    (["sweep", "--bias-seeds", "0-100000000000"], "at most 10,000"),
    (["sweep", "--bias-seeds", "0-999", "--seeds", "0-99"], "100,000 units"),
]


@pytest.mark.parametrize("argv, word", REFUSED_BEFORE_ANY_WORK, ids=[" ".join(argv[:3]) for argv, _ in REFUSED_BEFORE_ANY_WORK])
def test_a_refused_command_leaves_no_folder_and_no_stamp(capsys, tmp_path, argv, word):
    """A bad option is refused by its flag's name, and neither the ``--out`` folder (nor a
    parent it would have made) nor a stamp with the bad value is left: the corrected command
    then runs in the same folder."""
    out = tmp_path / "new" / "run"
    err = _fails_in_one_line(capsys, [*argv, "--out", str(out)], word)
    assert "Config." not in err  # the flag's name, not a config field's deeper down
    assert not (tmp_path / "new").exists()


def test_every_config_class_is_one_whose_fields_the_errors_name_as_flags():
    from dvrk_gym.cli.main import CONFIG_CLASSES

    found = {name for path in (ROOT / "dvrk_gym").rglob("*.py") for name in re.findall(r"^class (\w+Config)\b", path.read_text(), re.M)}
    assert found == set(CONFIG_CLASSES)


def test_a_path_that_looks_like_a_config_field_is_left_as_it_is(capsys, tmp_path):
    data = tmp_path / "LabConfig.data" / "x.npz"
    _fails_in_one_line(capsys, ["search", "--data", str(data), "--out", str(tmp_path / "o")], str(data))


def test_the_quiet_import_passes_on_what_a_failing_import_wrote(tmp_path):
    """A pybullet whose import writes its banner and a driver's error, then fails: the error's
    words reach stderr, the banner does not, and the ImportError propagates."""
    (tmp_path / "pybullet.py").write_text(
        'import os\nos.write(2, b"pybullet build time: x\\nlibGL error: no driver\\n")\nraise ImportError("no pybullet")\n'
    )
    code = (
        "from dvrk_gym.sim.physics.quiet_import import import_pybullet_quietly\n"
        "try:\n    import_pybullet_quietly()\nexcept ImportError as error:\n    print('raised:', error)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        env={**environment(), "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"},
        cwd=ROOT,
    )
    assert done.stdout.strip() == "raised: no pybullet"
    assert done.stderr.splitlines() == ["libGL error: no driver"], done.stderr


def test_a_refused_command_prints_one_line_without_pybullets_banner():
    """In a fresh process (where PyBullet's import prints its build time on stderr) a refused
    command's stderr is its one error line."""
    done = run_cli("baseline", "train", "--algo", "sac", "--n-envs", "0", timeout_s=120.0)
    assert done.returncode == 2
    assert done.stderr.splitlines() == ["dvrk-gym baseline train: error: --n-envs must be an int in [1, 64], got 0"], done.stderr


def test_a_refused_command_keeps_an_existing_folder_and_its_files(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    _fails_in_one_line(capsys, ["calibrate", "--epochs", "-1", "--out", str(tmp_path)], "--epochs")
    assert files_in(tmp_path) == {"notes.txt"}


def test_debride_names_a_file_given_as_the_calibration_folder(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("not a run")
    _fails_in_one_line(
        capsys, ["debride", "--calibration", str(tmp_path / "notes.txt"), "--out", str(tmp_path / "o")], "is a file, not a folder"
    )


def test_a_refused_command_keeps_an_empty_folder_the_user_had(capsys, tmp_path):
    """Only folders the command made go: an existing empty --out (here named through a folder
    that does not exist, "new/../keep") stays, refused after the folder check or not."""
    keep = tmp_path / "keep"
    keep.mkdir()
    _fails_in_one_line(capsys, ["baseline", "evaluate", "--model", "missing.zip", "--out", str(keep)], "missing.zip")
    _fails_in_one_line(
        capsys, ["baseline", "evaluate", "--model", "missing.zip", "--out", str(tmp_path / "new" / ".." / "keep")], "missing"
    )
    assert keep.is_dir() and not (tmp_path / "new").exists()


def test_a_refused_command_does_not_remove_folders_an_earlier_call_made(capsys, tmp_path):
    """In one process (tests, notebooks), a folder an earlier call made is not this command's to remove."""
    from dvrk_gym.cli.options import writable_folder

    made = writable_folder(tmp_path / "made")  # as an earlier command in this process would
    _fails_in_one_line(capsys, ["baseline", "evaluate", "--model", "missing.zip", "--out", str(tmp_path / "other")], "missing.zip")
    assert made.is_dir() and not (tmp_path / "other").exists()


def test_a_policy_that_raises_leaves_its_traceback_and_no_empty_folder(tmp_path):
    """A user's policy failing mid-run is no bad input: its error comes through as it is, and
    the --out the command made (with nothing yet written in it) goes, as for a refused command."""
    out = tmp_path / "new" / "sub"
    argv = ["evaluate", "--policy", "policies_for_tests:fails_on_its_first_step", "--episodes", "1", "--out", str(out)]
    with pytest.raises(RuntimeError, match="the policy's own bug"):
        main([*argv, "--resolution", "320", "180", "--no-progress"])
    assert not (tmp_path / "new").exists()


def test_sweep_refuses_an_out_that_is_a_file_before_announcing_its_grid(capsys, tmp_path):
    """It printed "sweep: 5 instruments x 1 seeds = 5 units on ..." and then the refusal."""
    (tmp_path / "afile").write_text("x")
    status = main(["sweep", "--out", str(tmp_path / "afile")])
    captured = capsys.readouterr()
    assert status == 2 and captured.out == "" and "is a file, not a folder" in captured.err


def test_a_subcommands_error_names_it_as_typed(capsys):
    _fails_in_one_line(capsys, ["baseline", "evaluate", "--model", "missing.zip"], "dvrk-gym baseline evaluate: error:")


def test_debride_picks_through_the_endoscope_its_calibration_was_made_with(small_calibration, tmp_path, capsys):
    """The calibration was made at 640 x 360; debride ran its picks at --resolution's default,
    1920 x 1080, and recorded that, with no word of the difference."""
    out = tmp_path / "out"
    argv = ["debride", "--calibration", str(small_calibration), "--trials", "1", "--out", str(out), "--no-progress"]
    assert main([*argv, "--bias", "paper", "--bias-seed", "0"]) == 0  # the folder's own instrument, given again
    capsys.readouterr()
    (cell,) = out.glob("*.json")
    assert json.loads(cell.read_text())["camera_resolution"] == [640, 360]


@pytest.mark.parametrize(
    "flags, word",
    [
        (["--bias", "severe"], "--bias severe differs from the paper"),
        (["--bias-seed", "3"], "--bias-seed 3 differs from the 0"),
        (["--resolution", "1920", "1080"], "--resolution [1920, 1080] differs from the [640, 360]"),
    ],
)
def test_debride_refuses_an_instrument_other_than_its_calibrations(small_calibration, tmp_path, capsys, flags, word):
    """The picks go through the calibration folder's instrument; a flag naming another one was
    ignored without a word (the trial table then said it was the folder's). It is refused
    before anything is written; the same flag with the folder's own value runs (above)."""
    out = tmp_path / "out"
    _fails_in_one_line(capsys, ["debride", "--calibration", str(small_calibration), "--out", str(out), *flags], word)
    assert not out.exists()


def _main_running(monkeypatch, func):
    """The command line's ``main``, each command's work replaced by ``func(args)``."""
    from dvrk_gym.cli import main as cli_main

    parser = cli_main.build_parser()
    parse = parser.parse_args

    def parse_and_replace(arguments=None):
        args = parse(arguments)
        args.func = func
        return args

    monkeypatch.setattr(parser, "parse_args", parse_and_replace)
    monkeypatch.setattr(cli_main, "build_parser", lambda: parser)
    return cli_main.main


@pytest.mark.parametrize(
    "argv, resumes",
    [
        (["calibrate", "--trajectories", "1"], True),
        (["evaluate", "--trajectories", "1"], True),
        (["evaluate", "--policy", "x:y"], False),
        (["debride", "--calibrate"], True),
        (["debride"], False),
        (["baseline", "train", "--algo", "sac", "--steps", "10"], False),  # before its first save: nothing kept
        (["search", "--quick"], False),
        (["collect", "--trajectories", "1"], False),
        (["demo", "--circles", "1"], False),
    ],
)
def test_ctrl_c_says_the_command_resumes_only_where_it_keeps_its_stages(capsys, tmp_path, monkeypatch, argv, resumes):
    def interrupted(args):
        raise KeyboardInterrupt

    main = _main_running(monkeypatch, interrupted)
    assert main([*argv, "--out", str(tmp_path / "out")]) == 130
    err = capsys.readouterr().err
    assert ("the same command resumes" in err) is resumes and ("nothing is kept" in err) is not resumes, err


def test_sigterm_stops_a_command_as_ctrl_c_does_and_says_so(capsys, tmp_path, monkeypatch):
    """SIGTERM (timeout, kill, a batch system) ended the process at once: no note, and its
    pool's semaphores left behind. Now it stops as Ctrl-C does, with the shell's status 143."""
    import signal
    import time

    def terminated(args):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)  # the signal's exception ends this at once
        raise AssertionError("SIGTERM did not stop the command")

    main = _main_running(monkeypatch, terminated)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["collect", "--trajectories", "1", "--out", str(tmp_path / "out")]) == 143
    assert "dvrk-gym collect: terminated (nothing is kept: run it again)" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is before  # the handler is the command's only


def test_ctrl_c_of_a_training_says_it_resumes_only_once_a_state_was_saved(capsys, tmp_path, monkeypatch):
    """It said "cached stages are kept: the same command resumes" before any save, and the
    folder held nothing but its lock."""
    from dvrk_gym.cli import main as cli_main
    from dvrk_gym.cli.baselines import TRAINING_STATE

    parser = cli_main.build_parser()
    parse = parser.parse_args

    def parse_and_interrupt(arguments=None):
        args = parse(arguments)

        def interrupted(args):
            raise KeyboardInterrupt

        args.func = interrupted
        return args

    monkeypatch.setattr(parser, "parse_args", parse_and_interrupt)
    monkeypatch.setattr(cli_main, "build_parser", lambda: parser)
    argv = ["baseline", "train", "--algo", "sac", "--steps", "10", "--out", str(tmp_path / "out")]
    assert cli_main.main(argv) == 130
    assert "no training state was saved yet (the first save comes after 500 env steps)" in capsys.readouterr().err
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / TRAINING_STATE).write_bytes(b"saved")
    assert cli_main.main(argv) == 130
    assert "its last saved training state is kept: the same command resumes from it" in capsys.readouterr().err


def test_search_on_a_collection_that_keeps_too_few_rows_names_the_file(capsys, tmp_path, unseen_phase1):
    """It said "--folds 2: the data has only 0 rows", as though the flag were at fault."""
    data = tmp_path / "phase1.npz"
    unseen_phase1(5).save(data)
    assert main(["search", "--data", str(data), "--folds", "2", "--out", str(tmp_path / "search")]) == 2
    assert f"--folds 2: {data} has only 0 rows that the cleaning keeps" in capsys.readouterr().err
    assert not (tmp_path / "search").exists()


@pytest.mark.parametrize("command", ["sweep", "reproduce"])
def test_workers_beside_a_scheduler_is_refused_not_ignored(capsys, tmp_path, command):
    """--workers 3 --scheduler ADDRESS ran on the cluster, the 3 ignored without a word."""
    from dvrk_gym.cli.main import main

    with pytest.raises(SystemExit) as stopped:
        main([command, "--workers", "3", "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "out")])
    assert stopped.value.code == 2 and "argument --scheduler: not allowed with argument --workers" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
