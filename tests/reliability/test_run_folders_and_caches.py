"""Run folders: one owner at a time, stale locks taken over, every write whole or absent,
and cached results cut short or tampered with named, moved aside and made again."""

import errno
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from faults import ROOT, environment

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.parallel.task_graph import Task, run_tasks
from dvrk_gym.utils import atomic
from dvrk_gym.utils.atomic import PARTIAL_MARK, atomic_open, atomic_path, atomic_savefig, atomic_write_text, partial_path
from dvrk_gym.utils.run_folder import LOCK_FILE, SOURCE_KEY, RunFolder, RunFolderBusy, check_made_here, read_settings
from dvrk_gym.utils.source_fingerprint import source_fingerprint

HOLDER = """
import sys, time
from dvrk_gym.utils.run_folder import RunFolder
folder = RunFolder(sys.argv[1], {"seed": 0})
print("holding", flush=True)
time.sleep(600)
"""


@pytest.fixture
def held_folder(tmp_path):
    """A run folder owned by another process (its pid), released at the end."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True, env=environment(), cwd=ROOT
    )
    try:
        assert holder.stdout.readline().strip() == "holding"
        yield tmp_path / "run", holder
    finally:
        holder.kill()
        holder.wait()


def test_a_second_process_gets_an_error_naming_the_folder_and_the_owner(held_folder):
    folder, holder = held_folder
    with pytest.raises(RunFolderBusy) as busy:
        RunFolder(folder, {"seed": 0})
    assert str(folder) in str(busy.value) and f"process {holder.pid}" in str(busy.value)


def test_reproduce_and_the_scheduler_refuse_a_folder_in_use(held_folder):
    from dvrk_gym.reproduce import ReproduceConfig, run_reproduce

    folder, holder = held_folder
    with pytest.raises(RunFolderBusy, match=f"process {holder.pid}"):
        run_reproduce(ReproduceConfig(out=folder, progress=False))
    assert not (folder / "tasks").exists()  # refused before anything ran
    with pytest.raises(RunFolderBusy):
        run_tasks([Task("a", dict)], cache_dir=folder, progress=False)


def test_a_killed_owners_lock_is_taken_over_with_a_message(held_folder, caplog):
    folder, holder = held_folder
    holder.kill()
    holder.wait()  # killed: the kernel dropped its lock; its pid is still written in the lock file
    assert json.loads((folder / LOCK_FILE).read_text())["pid"] == holder.pid
    with caplog.at_level(logging.WARNING, logger="dvrk_gym.utils.run_folder"), RunFolder(folder, {"seed": 0}):
        assert json.loads((folder / LOCK_FILE).read_text())["pid"] == os.getpid()
    assert f"taking over the lock process {holder.pid} left without releasing it" in caplog.text and str(folder) in caplog.text


def test_a_clean_release_leaves_no_stale_owner(tmp_path, caplog):
    with RunFolder(tmp_path):
        pass
    assert (tmp_path / LOCK_FILE).read_text() == ""
    with caplog.at_level(logging.WARNING), RunFolder(tmp_path):
        pass
    assert "stale" not in caplog.text


def test_a_file_named_as_the_folder_is_refused(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="is a file, not a folder"):
        RunFolder(tmp_path / "file")


# ---------------------------------------------------------------- atomic writes
def test_a_writer_that_fails_half_way_leaves_the_old_file(tmp_path):
    path = atomic_write_text(tmp_path / "result.json", '{"old": true}')
    with pytest.raises(RuntimeError, match="disk full"), atomic_open(path, "w") as stream:
        stream.write('{"new": tr')
        raise RuntimeError("disk full")
    assert path.read_text() == '{"old": true}'
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]  # no temporary file left


def test_a_full_disk_names_the_file_it_could_not_write(tmp_path):
    """A write's ENOSPC names no file: the command line's one line said only "No space left on device"."""
    path = atomic_write_text(tmp_path / "result.json", '{"old": true}')
    with pytest.raises(OSError, match=r"\[Errno 28\] No space left on device: '.*result\.json'$") as raised, atomic_open(path, "w"):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(path)
    with pytest.raises(PermissionError, match="other.txt"), atomic_open(tmp_path / "b.txt", "w"):
        raise PermissionError(errno.EACCES, "Permission denied", "other.txt")  # one that names its file is kept as it is
    assert path.read_text() == '{"old": true}' and sorted(p.name for p in tmp_path.iterdir()) == ["result.json"]


def test_a_figure_that_cannot_be_drawn_leaves_nothing(tmp_path):
    class Broken:
        def savefig(self, path, **options):
            Path(path).write_bytes(b"\x89PNG half")
            raise ValueError("bad figure")

    with pytest.raises(ValueError, match="bad figure"):
        atomic_savefig(Broken(), tmp_path / "figure.png")
    assert list(tmp_path.iterdir()) == []


def test_a_writer_that_writes_nothing_is_an_error(tmp_path):
    with pytest.raises(OSError, match="nothing was written"), atomic_path(tmp_path / "model.zip"):
        pass
    assert list(tmp_path.iterdir()) == []


def test_temporary_files_of_a_killed_write_are_removed_when_the_folder_is_opened(tmp_path):
    leftover = partial_path(tmp_path / "sub" / "phase1.npz")
    leftover.parent.mkdir()
    leftover.write_bytes(b"half")
    (tmp_path / "keep.json").write_text("{}")
    with RunFolder(tmp_path):
        assert not leftover.exists() and (tmp_path / "keep.json").exists()


# ---------------------------------------------------------------- corrupt caches
def _made_again(folder, name, load, value, save, caplog):
    """Load ``name`` from ``folder`` after it was damaged: the value made again, the warning and the file set aside."""
    made = []
    with caplog.at_level(logging.WARNING, logger="dvrk_gym.utils.run_folder"):
        result = folder.cached(name, make=lambda: made.append(1) or value, load=load, save=save)
    assert made == [1]
    assert name in caplog.text and "moved it to" in caplog.text
    assert folder.file(name + ".corrupt").exists() and folder.file(name).exists()
    return result


@pytest.mark.parametrize(
    "damage",
    [lambda data: data[: len(data) // 2], lambda data: b"", lambda data: b"PK\x03\x04" + bytes(100), lambda data: data[:-10]],
    ids=["half", "empty", "zip-header-only", "tail-cut"],
)
def test_a_cut_phase2_file_is_moved_aside_and_made_again(tmp_path, caplog, damage):
    rng = np.random.default_rng(0)
    data = Phase2Data(rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), np.arange(5))
    with RunFolder(tmp_path) as folder:
        data.save(folder.file("phase2.npz"))
        folder.file("phase2.npz").write_bytes(damage(folder.file("phase2.npz").read_bytes()))
        again = _made_again(folder, "phase2.npz", Phase2Data.load, data, lambda value, path: value.save(path), caplog)
        assert np.array_equal(again.corrected, data.corrected)
        assert np.array_equal(Phase2Data.load(folder.file("phase2.npz")).corrected, data.corrected)


def test_a_tampered_model_file_is_moved_aside_and_made_again(tmp_path, caplog):
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), rng.uniform(0.17, 0.2, 40), rng.uniform(-1, 1, (40, 3))])
    model = DNNCalibrator(hidden_layers=1, units=4, epochs=1, progress=False).fit(X, X[:, :3])
    with RunFolder(tmp_path) as folder:
        model.save(folder.file("dnn.zip"))
        blob = bytearray(folder.file("dnn.zip").read_bytes())
        blob[len(blob) // 2] ^= 0xFF
        folder.file("dnn.zip").write_bytes(bytes(blob))
        _made_again(folder, "dnn.zip", DNNCalibrator.load, model, lambda value, path: value.save(path), caplog)
        # cached() returns the remade value itself; what counts is the file it wrote again
        assert np.array_equal(DNNCalibrator.load(folder.file("dnn.zip")).predict(X), model.predict(X))


def test_every_damaged_copy_is_kept_and_an_earlier_one_even_a_folder_does_not_block_the_next(tmp_path, caplog):
    def load(path):
        return json.loads(path.read_text())

    def save(value, path):
        path.write_text(json.dumps(value))

    with RunFolder(tmp_path) as folder:
        folder.file("a.json.corrupt").mkdir()  # set aside by hand, or a folder that stood at a.json
        (folder.file("a.json.corrupt") / "kept.txt").write_text("evidence")
        for damage in ("one", "two"):
            folder.file("a.json").write_text(damage)
            assert folder.cached("a.json", make=lambda: {"v": 1}, load=load, save=save) == {"v": 1}
    assert [(tmp_path / f"a.json.corrupt.{n}").read_text() for n in (2, 3)] == ["one", "two"]
    assert (tmp_path / "a.json.corrupt" / "kept.txt").read_text() == "evidence" and "a.json.corrupt.3" in caplog.text


def test_set_aside_gives_up_with_a_clear_error_when_too_many_copies_are_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic, "MAX_SET_ASIDE", 2)
    for name in ("a.npz", "a.npz.corrupt", "a.npz.corrupt.2"):
        (tmp_path / name).write_text(name)
    with pytest.raises(FileExistsError, match=r"2 damaged copies of .*a\.npz are set aside already"):
        atomic.set_aside(tmp_path / "a.npz")
    assert (tmp_path / "a.npz").read_text() == "a.npz"


def _record(name: str, log: str) -> dict:
    with open(log, "a") as handle:
        handle.write(name + "\n")
    return {"name": name}


@pytest.mark.parametrize(
    "content", ['{"name": "a", "wall_s": 0.1', "", "[]", '{"name": "a"}', "\x00\x01"], ids=["cut", "empty", "list", "no-wall", "binary"]
)
def test_a_damaged_task_result_is_named_moved_aside_and_run_again(tmp_path, caplog, content):
    log = str(tmp_path / "log.txt")
    graph = [Task("a", _record, {"name": "a", "log": log}), Task("b", _record, {"name": "b", "log": log}, needs=("a",))]
    run_tasks(graph, cache_dir=tmp_path / "cache", progress=False)
    (tmp_path / "cache" / "a.json").write_text(content)
    with caplog.at_level(logging.WARNING, logger="dvrk_gym.utils.run_folder"):
        results = run_tasks(graph, cache_dir=tmp_path / "cache", progress=False)
    assert "a.json is unreadable" in caplog.text
    assert Path(log).read_text().split() == ["a", "b", "a"]  # only the damaged task ran again
    assert results["a"]["name"] == "a" and not results["a"]["cached"] and results["b"]["cached"]
    assert (tmp_path / "cache" / "a.json.corrupt").read_text() == content


def test_a_damaged_settings_stamp_is_an_error_naming_it(tmp_path):
    (tmp_path / "settings.json").write_text('{"seed": ')
    with pytest.raises(ValueError, match="settings.json is unreadable"):
        RunFolder(tmp_path, {"seed": 0})
    (tmp_path / "settings.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match="holds list, not the settings object"):
        read_settings(tmp_path, "settings.json")


def test_results_left_without_a_stamp_are_never_taken_as_a_new_runs(tmp_path):
    """Deleting the stamp (as an unreadable one's error said) let a run with other settings
    load the old results and stamp the folder with its own: models of another instrument."""
    with RunFolder(tmp_path, {"bias": "paper"}) as folder:
        folder.write_json("model.json", {"made with": "paper"})
    (tmp_path / "settings.json").unlink()
    with pytest.raises(ValueError, match=r"holds files but no settings stamp \(settings.json\): \['model.json'\]"):
        RunFolder(tmp_path, {"bias": "none"})
    assert not (tmp_path / "settings.json").exists()  # not stamped with the refused settings
    (tmp_path / "model.json").unlink()
    with RunFolder(tmp_path, {"bias": "none"}) as folder:  # an empty folder (but its lock) is a new run's
        assert folder.read_json("model.json") is None


def test_results_in_a_subfolder_without_a_stamp_are_never_taken_as_a_new_runs(tmp_path):
    """reproduce and sweep cache their results in tasks/ and units/: with the stamp deleted, a run
    with other settings loaded every cached task (the check looked at the folder's own files only)."""
    with RunFolder(tmp_path, {"seed": 0}) as folder:
        (tmp_path / "tasks").mkdir()
        folder.write_json("tasks/calibration.json", {"seed": 0})
    (tmp_path / "settings.json").unlink()
    with pytest.raises(ValueError, match=r"holds files but no settings stamp \(settings.json\): \['tasks/calibration.json'\]"):
        RunFolder(tmp_path, {"seed": 7})


def test_a_folder_holding_other_stamped_runs_and_locks_only_is_a_new_runs(tmp_path):
    """Stamped run folders below (runs/cal) check their own settings, and a lock is no result."""
    with RunFolder(tmp_path / "cal", {"seed": 0}) as cal:
        cal.write_json("model.json", {"seed": 0})
    (tmp_path / "tasks").mkdir()
    (tmp_path / "tasks" / "run.lock").write_text("")
    with RunFolder(tmp_path, {"seed": 7}):
        pass
    with RunFolder(tmp_path / "unstamped") as cache:  # a cache of another run, with no stamp: its files are unknown
        cache.write_json("result.json", {"seed": 0})
    (tmp_path / "settings.json").unlink()
    with pytest.raises(ValueError, match=r"\['unstamped/result.json'\]"):
        RunFolder(tmp_path, {"seed": 8})


def test_a_refused_folder_keeps_its_temporary_files(tmp_path):
    """Opening a folder removed every temporary file below it before checking the folder was the
    run's: a refused --out lost an unrelated program's files mid-write."""
    (tmp_path / "notes.md").write_text("mine")
    (tmp_path / "drafts").mkdir()
    partial = tmp_path / "drafts" / f".report{PARTIAL_MARK}.md"
    partial.write_text("being written")
    with pytest.raises(ValueError, match="holds files but no settings stamp"):
        RunFolder(tmp_path, {"seed": 0})
    assert partial.read_text() == "being written"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["drafts", "notes.md"]  # nor a lock of the refused run


def _stamped_by(folder: Path, source) -> dict[str, bytes]:
    """A run folder with a result, its stamp's source fingerprint replaced by ``source`` (left out
    when None), as another dvrk_gym would have left it; returns its files' bytes (not the lock)."""
    with RunFolder(folder, {"seed": 0}) as run:
        run.write_json("result.json", {"x": 1.5})
    stamp = json.loads((folder / "settings.json").read_text())
    del stamp[SOURCE_KEY]
    if source is not None:
        stamp[SOURCE_KEY] = source
    (folder / "settings.json").write_text(json.dumps(stamp))
    return {path.name: path.read_bytes() for path in folder.iterdir() if path.name != LOCK_FILE}


@pytest.mark.parametrize(
    ("source", "message"),
    [
        (
            {"version": "0.0.9", "sha256": "ab" * 32},
            r"holds results made by another version of dvrk_gym's simulator \(dvrk_gym 0\.0\.9, source sha256 abababababab; this is "
            + r"dvrk_gym .*, source sha256 {here}\), which would be mixed",
        ),
        (None, r"holds results made by an older dvrk_gym: its stamp \(settings\.json\) has no source fingerprint, so which simulator"),
        ({"version": "0.0.9"}, r"older dvrk_gym: its stamp \(settings\.json\) has an unreadable source fingerprint \(\{'version'"),
    ],
    ids=["another version", "no fingerprint", "unreadable fingerprint"],
)
def test_a_folder_of_another_dvrk_gym_is_refused_and_left_as_it_was(tmp_path, source, message):
    before = _stamped_by(tmp_path, source)
    with pytest.raises(ValueError, match=message.replace("{here}", source_fingerprint().sha256[:12])) as refused:
        RunFolder(tmp_path, {"seed": 0})
    assert str(refused.value).startswith(str(tmp_path)) and str(refused.value).endswith(
        "use another --out, or delete the folder to make them again with this version"
    )
    assert {path.name: path.read_bytes() for path in tmp_path.iterdir() if path.name != LOCK_FILE} == before
    assert read_settings(tmp_path, "settings.json") == {"seed": 0}  # a reader still reads it
    with pytest.raises(ValueError, match=message.replace("{here}", source_fingerprint().sha256[:12])) as refused:
        check_made_here(tmp_path, "settings.json", remedy="make it again")  # a reader that mixes it with this version's
    assert str(refused.value).endswith("; make it again")
    with RunFolder(tmp_path) as unchecked:  # without settings: no check, as before
        assert unchecked.read_json("result.json") == {"x": 1.5}


def test_a_reader_passes_a_folder_this_dvrk_gym_made_and_one_without_a_stamp(tmp_path):
    with RunFolder(tmp_path / "made", {"seed": 0}) as run:
        run.write_json("result.json", {"x": 1.5})
    check_made_here(tmp_path / "made", "settings.json", remedy="make it again")
    check_made_here(tmp_path / "bare", "settings.json", remedy="make it again")  # no stamp: not the check's question


def test_the_stamps_source_key_is_no_setting(tmp_path):
    with pytest.raises(ValueError, match=f"'{SOURCE_KEY}' is reserved for the stamp's source fingerprint"):
        RunFolder(tmp_path, {"seed": 0, SOURCE_KEY: "mine"})
    assert not (tmp_path / "settings.json").exists()


def test_a_kill_during_a_write_leaves_the_old_result(tmp_path):
    """A process killed while writing (SIGKILL, no clean-up): the result is the old one or the new one, whole."""
    path = tmp_path / "result.json"
    atomic_write_text(path, json.dumps({"value": "old"}))
    writer = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom dvrk_gym.utils.atomic import atomic_open\n"
            "with atomic_open(sys.argv[1], 'w') as f:\n    f.write('{\"value\": ')\n    f.flush()\n    print('writing', flush=True)\n"
            "    time.sleep(600)\n",
            str(path),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env=environment(),
    )
    assert writer.stdout.readline().strip() == "writing"
    writer.kill()
    writer.wait()
    time.sleep(0.1)
    assert json.loads(path.read_text()) == {"value": "old"}
    assert len(list(tmp_path.glob(".result.*.partial.json"))) == 1  # what the killed writer left
    with RunFolder(tmp_path):
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted([LOCK_FILE, "result.json"])  # the half write is gone


def _die_once(flag: str) -> dict:
    """Kill this (worker) process with SIGKILL the first time; return normally once ``flag`` exists."""
    if not Path(flag).exists():
        Path(flag).write_text("died once")
        os.kill(os.getpid(), 9)
    return {"survived": True}


def test_a_worker_killed_mid_task_fails_the_run_with_its_name_and_the_rerun_completes(tmp_path):
    from dvrk_gym.parallel.task_graph import TaskError

    log = str(tmp_path / "log.txt")
    graph = [Task("fine", _record, {"name": "fine", "log": log}), Task("doomed", _die_once, {"flag": str(tmp_path / "flag")}, cost_s=9)]
    with pytest.raises(TaskError, match=r"a worker process died while running \[[^]]*'doomed'"):
        run_tasks(graph, cache_dir=tmp_path / "cache", workers=2, progress=False)
    results = run_tasks(graph, cache_dir=tmp_path / "cache", workers=2, progress=False)
    assert results["doomed"] == {**results["doomed"], "survived": True, "cached": False}


def test_a_folder_holding_only_its_stamp_takes_a_new_runs_settings(tmp_path):
    """A run refused after stamping its folder (a resolution whose circles the endoscope cannot
    find is only known once the world renders) left the folder refusing the corrected run."""
    RunFolder(tmp_path, {"camera_resolution": [128, 72]}).close()
    (tmp_path / ".settings.json.tmp-1").write_text("")  # a temporary file is no result
    with RunFolder(tmp_path, {"camera_resolution": [320, 180]}) as folder:
        folder.write_json("model.json", {"made with": [320, 180]})
    assert read_settings(tmp_path, "settings.json") == {"camera_resolution": [320, 180]}
    with pytest.raises(ValueError, match=r"other settings \(camera_resolution: \[320, 180\] there, \[128, 72\] here"):
        RunFolder(tmp_path, {"camera_resolution": [128, 72]})  # now it holds a result: refused, and left as it was
    assert read_settings(tmp_path, "settings.json") == {"camera_resolution": [320, 180]}


def test_a_folder_whose_subfolders_hold_no_result_takes_a_new_runs_settings_and_one_holding_one_does_not(tmp_path):
    """reproduce makes figures/, tasks/ and calibration/ (a run folder of its own) right after
    stamping, and a sweep units/: a run refused there still held no result."""
    RunFolder(tmp_path, {"seed": 0}).close()
    (tmp_path / "figures").mkdir()
    RunFolder(tmp_path / "calibration", {"seed": 0}).close()
    RunFolder(tmp_path, {"seed": 1}).close()
    assert read_settings(tmp_path, "settings.json") == {"seed": 1}
    with RunFolder(tmp_path / "calibration", {"seed": 1}) as calibration:
        calibration.write_json("phase1.json", {"seed": 1})
    with pytest.raises(ValueError, match="other settings"):
        RunFolder(tmp_path, {"seed": 2})


def test_a_second_opening_in_the_same_process_never_restamps_the_folder(tmp_path):
    """The lock is re-entrant: an outer run that had made nothing yet had its stamp replaced."""
    with RunFolder(tmp_path, {"seed": 0}) as outer:
        with pytest.raises(ValueError, match="other settings"):
            RunFolder(tmp_path, {"seed": 1})
        outer.write_json("result.json", {"seed": 0})
    assert read_settings(tmp_path, "settings.json") == {"seed": 0}
