"""The source fingerprint: which dvrk_gym made a run folder's results, and run folders that
refuse the results of another one."""

import importlib.metadata
import json
import shutil
from pathlib import Path

import pytest

import dvrk_gym
from dvrk_gym.utils import source_fingerprint as fingerprints
from dvrk_gym.utils.run_folder import SOURCE_KEY, RunFolder, read_settings
from dvrk_gym.utils.source_fingerprint import PACKAGE_ROOT, SourceFingerprint, package_files, source_fingerprint, tree_sha256


@pytest.fixture
def small_tree(tmp_path):
    """A small package tree: a copy of dvrk_gym/utils (its modules only) and py.typed."""
    root = tmp_path / "dvrk_gym"
    shutil.copytree(PACKAGE_ROOT / "utils", root / "utils", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    shutil.copy(PACKAGE_ROOT / "py.typed", root / "py.typed")
    return root


@pytest.fixture
def installed_as(monkeypatch):
    """Make this process's fingerprint that of another package tree: ``installed_as(root)``, as a
    process started after installing that tree would see it (the real package is not touched)."""

    def install(root):
        monkeypatch.setattr(fingerprints, "PACKAGE_ROOT", root)
        source_fingerprint.cache_clear()  # a new process: computed again

    yield install
    source_fingerprint.cache_clear()  # the real package's again (monkeypatch restores PACKAGE_ROOT after this)


def test_the_fingerprint_is_made_once_per_process_from_the_installed_package():
    first = source_fingerprint()
    assert source_fingerprint() is first  # functools.cache: hashed once
    assert Path(dvrk_gym.__file__).resolve().parent == PACKAGE_ROOT
    assert first.sha256 == tree_sha256(PACKAGE_ROOT) and len(first.sha256) == 64
    assert first.version == importlib.metadata.version("dvrk-gym")
    files = package_files(PACKAGE_ROOT)
    for covered in ("__init__.py", "sim/identified.py", "utils/source_fingerprint.py", "py.typed", "data/seita2018_phase1/X_train.npy"):
        assert covered in files
    assert not [name for name in files if "__pycache__" in name or name.endswith((".pyc", ".nbi", ".nbc"))]
    assert "baselines/README.md" not in files  # in the checkout, not in a wheel
    assert first.short() == f"dvrk_gym {first.version}, source sha256 {first.sha256[:12]}"
    assert SourceFingerprint.from_json(json.loads(json.dumps(first.to_json()))) == first


def test_a_changed_added_or_renamed_file_changes_the_digest_and_caches_do_not(small_tree):
    before = tree_sha256(small_tree)
    assert tree_sha256(small_tree) == before
    module = small_tree / "utils" / "checks.py"
    text = module.read_bytes()
    module.write_bytes(text + b"\n")
    assert tree_sha256(small_tree) != before
    module.write_bytes(text)
    assert tree_sha256(small_tree) == before
    module.rename(small_tree / "utils" / "checks2.py")
    assert tree_sha256(small_tree) != before
    (small_tree / "utils" / "checks2.py").rename(module)
    (small_tree / "data").mkdir()
    (small_tree / "data" / "table.npy").write_bytes(b"\x93NUMPY")
    assert tree_sha256(small_tree) != before
    (small_tree / "data" / "table.npy").unlink()
    (small_tree / "data").rmdir()
    # what Python and numba write while the package runs, and hidden files, are not the code
    (small_tree / "utils" / "__pycache__").mkdir()
    (small_tree / "utils" / "__pycache__" / "checks.cpython-311.pyc").write_bytes(b"bytecode")
    (small_tree / "utils" / "__pycache__" / "kernels._hypot-117.py311.nbi").write_bytes(b"numba index")
    (small_tree / "utils" / "kernels._hypot-117.py311.1.nbc").write_bytes(b"numba data")
    (small_tree / "utils" / ".checks.py.swp").write_bytes(b"editor")
    # nor what a wheel would not install: a folder's README, an editor's backup, a merge's leftovers
    (small_tree / "utils" / "README.md").write_text("notes")
    (small_tree / "utils" / "checks.py~").write_bytes(text)
    (small_tree / "utils" / "checks.py.orig").write_bytes(text)
    assert tree_sha256(small_tree) == before


def test_the_version_is_none_without_metadata(monkeypatch):
    monkeypatch.setattr(fingerprints, "DISTRIBUTION", "dvrk-gym-not-installed")
    assert fingerprints.package_version() is None
    assert SourceFingerprint(version=None, sha256="ab" * 32).short() == "dvrk_gym (version unknown), source sha256 abababababab"


@pytest.mark.parametrize(
    "value", [None, "ab" * 32, {"sha256": "ab" * 32}, {"version": 1, "sha256": "ab"}, {"version": None, "sha256": 5}, ["ab"]]
)
def test_a_stamps_fingerprint_that_is_not_one_reads_as_none(value):
    assert SourceFingerprint.from_json(value) is None


def test_a_folder_made_before_an_upgrade_is_refused_after_it_and_reused_before(small_tree, installed_as, tmp_path):
    installed_as(small_tree)
    old = source_fingerprint()
    with RunFolder(tmp_path / "run", {"seed": 0}) as folder:
        folder.write_json("result.json", {"x": 1})
    assert json.loads((tmp_path / "run" / "settings.json").read_text())[SOURCE_KEY] == old.to_json()
    with RunFolder(tmp_path / "run", {"seed": 0}) as folder:  # the same simulator: reused
        assert folder.read_json("result.json") == {"x": 1}
    (small_tree / "utils" / "checks.py").write_text((small_tree / "utils" / "checks.py").read_text() + "\n# an upgrade\n")
    installed_as(small_tree)
    new = source_fingerprint()
    assert new.sha256 != old.sha256 and new.version == old.version
    with pytest.raises(ValueError) as refused:
        RunFolder(tmp_path / "run", {"seed": 0})
    assert f"holds results made by another version of dvrk_gym's simulator ({old.short()}; this is {new.short()})" in str(refused.value)
    assert read_settings(tmp_path / "run", "settings.json") == {"seed": 0}
