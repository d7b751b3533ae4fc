"""Convert the authors' records of their calibration table's runs into the packaged npz, without unpickling.

The paper's table "Calibration Error Results (In Pixels)" was measured by
``scripts/click_and_crop_v3.py`` of :data:`dvrk_gym.paper.AUTHORS_CODE`, run once per method and
yaw setting (the network: versions 20-25, with the forests 30-35, the rigid body 40-45; their
notes, ``images/visuals/README.md``). Each run appended one record per circle to
``config/calibration_results/data_vXY.p``: where the robot was sent and where it reported
itself, and the circle's and the end effector's pixels in the left image. Their Phase II,
``scripts/human_guidance_auto.py`` (versions 20-24 and 40-44, one per fixed yaw), appended the
network's prediction and the robot's reported pose before and after a person pushed its jaws
onto each circle to ``data_human_guided_vXY.p``.

The records are Python 2 pickles (protocol 0). They are read here by a small stack machine
for the handful of opcodes they use (dicts, lists, tuples, floats, ints, strings, and numpy
arrays rebuilt from their raw bytes): nothing is imported or called, shared objects stay
shared and nesting is bounded, so a tampered file can only fail to parse. Run once, from a clone of the authors' repository:

    python benchmarks/convert_authors_table_runs.py --authors-repo PATH \
        --out dvrk_gym/data/seita2018_table_runs/table_runs.npz
"""

from __future__ import annotations

import argparse
import codecs
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym.utils.atomic import atomic_open

TABLE_RUNS: dict[str, tuple[int, ...]] = {
    "DNN": (24, 23, 22, 21, 20, 25),
    "DNN+RF": (34, 33, 32, 31, 30, 35),
    "RBT": (44, 43, 42, 41, 40, 45),
}
"""The authors' version numbers of each method's six runs, in the table's setting order (yaw -90,
-45, 0, 45, 90, random)."""
PHASE2_RUNS: tuple[int, ...] = (24, 23, 22, 21, 20, 44, 43, 42, 41, 40)
"""The authors' Phase II files: two rounds of the five yaws, -90 to 90 each (round 0 on the day
of the network's runs, 1 September 2017; round 1 on the rigid body's, 6 September)."""
MAX_FILE_BYTES = 1_000_000
"""The largest record file read, bytes (the authors' are under 50 kB)."""
MAX_NESTING = 64
"""The deepest a record's containers may nest while it is read (the authors' nest 4 deep)."""

_MARK = object()


class _Global:
    """A name a pickle refers to; never imported."""

    def __init__(self, name: str) -> None:
        self.name = name


class _Reduce:
    """A call a pickle asks for; only numpy's array and dtype rebuilds are ever evaluated, by hand."""

    def __init__(self, function: _Global, arguments: Any) -> None:
        self.function, self.arguments, self.state = function, arguments, None


def _resolve(value: Any, done: dict[int, Any]) -> Any:
    """``value`` with numpy's rebuilds evaluated by hand. An object the record refers to more
    than once (the memo's ``g``) is resolved once and shared, as unpickling would share it,
    so a record cannot make this copy it exponentially often; a container is registered
    before its items, so one that holds itself is no endless loop either."""
    key = id(value)
    if key in done:
        return done[key]
    if isinstance(value, _Reduce):
        if value.function.name == "numpy.core.multiarray._reconstruct":
            # (version, shape, dtype, fortran, raw bytes); an ndarray subclass (tfx's frames) wraps it in a pair
            state = value.state[0] if isinstance(value.state[0], tuple) else value.state
            _, shape, dtype, fortran, raw = state
            resolved: Any = np.frombuffer(raw, dtype=_resolve(dtype, done)).reshape(shape, order="F" if fortran else "C").copy()
        elif value.function.name == "numpy.dtype":
            code, order = value.arguments[0].decode(), value.state[1].decode()
            resolved = np.dtype(order + code if order in "<>" else code)
        else:
            raise ValueError(f"the record calls {value.function.name}, which is not a numpy array or dtype")
    elif isinstance(value, dict):
        resolved = done[key] = {}
        resolved.update({item_key: _resolve(item, done) for item_key, item in value.items()})
    elif isinstance(value, list):
        resolved = done[key] = []
        resolved.extend(_resolve(item, done) for item in value)
    elif isinstance(value, tuple):
        resolved = tuple(_resolve(item, done) for item in value)
    else:
        resolved = value
    done[key] = resolved
    return resolved


def _line_end(data: bytes, start: int) -> int:
    end = data.find(b"\n", start)
    if end < 0:
        raise ValueError(f"not a file of protocol-0 records as the authors wrote them: a line from byte {start} has no end")
    return end


def read_protocol0_records(data: bytes) -> list[Any]:
    """The objects of a file of protocol-0 pickles appended one after another, read without unpickling.

    Nothing the records name is imported or called (numpy arrays and dtypes are rebuilt from
    their bytes by hand), objects they share stay shared, and they may nest at most
    :data:`MAX_NESTING` deep.

    Raises:
        ValueError: on an opcode outside the few the authors' records use, a call of anything
            but numpy's rebuilds, nesting too deep, or a truncated file.
    """
    records, i = [], 0
    try:
        while i < len(data):
            stack: list[Any] = []
            marks: list[int] = []  # where each open mark sits in the stack
            memo: dict[int, Any] = {}
            while True:
                op = chr(data[i])
                i += 1
                if op in "SFIpgcL":
                    end = _line_end(data, i)
                    line, i = data[i:end], end + 1
                if op == "(":
                    if len(marks) >= MAX_NESTING:
                        raise ValueError(f"a record nests deeper than {MAX_NESTING} (byte {i - 1})")
                    marks.append(len(stack))
                    stack.append(_MARK)
                elif op in "dlt":
                    start = marks.pop()
                    items = stack[start + 1 :]
                    del stack[start:]
                    stack.append(
                        dict(zip(items[::2], items[1::2], strict=True)) if op == "d" else list(items) if op == "l" else tuple(items)
                    )
                elif op == "S":
                    stack.append(codecs.escape_decode(line[1:-1])[0])
                elif op == "F":
                    stack.append(float(line))
                elif op == "I":
                    stack.append({b"00": False, b"01": True}[line] if line in (b"00", b"01") else int(line))
                elif op == "L":
                    stack.append(int(line.rstrip(b"L")))
                elif op == "N":
                    stack.append(None)
                elif op == "p":
                    memo[int(line)] = stack[-1]
                elif op == "g":
                    stack.append(memo[int(line)])
                elif op == "c":
                    end = _line_end(data, i)
                    name, i = f"{line.decode()}.{data[i:end].decode()}", end + 1
                    stack.append(_Global(name))
                elif op == "R":
                    arguments = stack.pop()
                    stack.append(_Reduce(stack.pop(), arguments))
                elif op == "b":
                    state = stack.pop()
                    stack[-1].state = state
                elif op == "a":
                    item = stack.pop()
                    stack[-1].append(item)
                elif op == "s":
                    item, key = stack.pop(), stack.pop()
                    stack[-1][key.decode() if isinstance(key, bytes) else key] = item
                elif op == ".":
                    break
                else:
                    raise ValueError(f"opcode {op!r} at byte {i - 1} is not one the authors' records use")
            records.append(_resolve(stack.pop(), {}))
    except RecursionError as error:
        raise ValueError(f"a record nests its objects too deep to read (byte {i})") from error
    except (IndexError, KeyError, AttributeError, TypeError) as error:
        raise ValueError(f"not a file of protocol-0 records as the authors wrote them (byte {i}): {error!r}") from error
    return records


def _read(path: Path) -> list[dict[str, Any]]:
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ValueError(f"{path} is {size} bytes; the authors' records are under {MAX_FILE_BYTES}")
    return read_protocol0_records(path.read_bytes())


def _position(value: Any) -> np.ndarray:
    """A position (3,) in metres from a list of three or a 4 x 4 frame."""
    array = np.asarray(value, dtype=np.float64)
    return array[:3, 3] if array.shape == (4, 4) else array.reshape(3)


def convert(authors_repo: Path) -> dict[str, np.ndarray]:
    """The arrays of the packaged file (see its README) from a clone of the authors' repository."""
    folder = authors_repo / "config" / "calibration_results"
    touches: dict[str, list[Any]] = {
        key: []
        for key in ("method", "setting", "circle_px", "end_effector_px", "sent", "reported", "sent_rotation_deg", "reported_rotation_deg")
    }
    for method, versions in TABLE_RUNS.items():
        for setting, version in enumerate(versions):
            for record in _read(folder / f"data_v{version}.p"):
                touches["method"].append(method)
                touches["setting"].append(setting)
                touches["circle_px"].append(record["center_target_pixels"])
                touches["end_effector_px"].append(record["center_actual_pixels"])
                touches["sent"].append(_position(record["target_pos"]))
                touches["reported"].append(_position(record["actual_pos"]))
                touches["sent_rotation_deg"].append(np.asarray(record["target_rot"], dtype=np.float64))
                touches["reported_rotation_deg"].append(np.asarray(record["actual_rot"], dtype=np.float64))
    pushes: dict[str, list[Any]] = {key: [] for key in ("yaw_deg", "round", "predicted", "before", "after")}
    for version in PHASE2_RUNS:
        for record in _read(folder / f"data_human_guided_v{version}.p"):
            pushes["yaw_deg"].append((-90.0, -45.0, 0.0, 45.0, 90.0)[4 - version % 10])
            pushes["round"].append(version // 40)
            pushes["predicted"].append(_position(record["original_robot_point_prediction"]))
            pushes["before"].append(_position(record["measured_robot_point_before_human_change"]))
            pushes["after"].append(_position(record["measured_robot_point_after_human_change"]))
    return {
        "touch_method": np.array(touches["method"]),
        "touch_setting": np.array(touches["setting"], dtype=np.int64),
        "touch_circle_px": np.array(touches["circle_px"], dtype=np.int64),
        "touch_end_effector_px": np.array(touches["end_effector_px"], dtype=np.int64),
        "touch_sent_m": np.array(touches["sent"]),
        "touch_reported_m": np.array(touches["reported"]),
        "touch_sent_rotation_deg": np.array(touches["sent_rotation_deg"]),
        "touch_reported_rotation_deg": np.array(touches["reported_rotation_deg"]),
        "push_yaw_deg": np.array(pushes["yaw_deg"]),
        "push_round": np.array(pushes["round"], dtype=np.int64),
        "push_predicted_m": np.array(pushes["predicted"]),
        "push_before_m": np.array(pushes["before"]),
        "push_after_m": np.array(pushes["after"]),
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--authors-repo", type=Path, required=True, help="a clone of the authors' repository")
    parser.add_argument("--out", type=Path, required=True, help="the npz to write")
    args = parser.parse_args()
    arrays = convert(args.authors_repo)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(args.out) as stream:
        np.savez(stream, **arrays)
    print(f"wrote {args.out}: {len(arrays['touch_method'])} touches, {len(arrays['push_yaw_deg'])} Phase II pushes")
