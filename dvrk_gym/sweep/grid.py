"""The grid of a sweep: instruments x calibrators x seeds, and the settings every cell shares.

A cell is (instrument, calibrator, seed). One calibration run on an instrument with a seed
makes all three of the paper's calibrators, so the unit of work is (instrument, seed):
:class:`Unit`, which fills one row per calibrator.
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import operator
import re
from dataclasses import dataclass
from typing import Any

from dvrk_gym.calibration.pipeline import CALIBRATOR_FILES, PipelineConfig

CALIBRATORS: tuple[str, ...] = tuple(CALIBRATOR_FILES)
"""The calibrators a sweep knows, by their command-line names: ``rbt``, ``dnn``, ``dnn+rf``."""
METHOD_NAMES = {"rbt": "RBT", "dnn": "DNN", "dnn+rf": "DNN+RF"}
"""Each calibrator's name in the calibration table (and in :mod:`dvrk_gym.paper`)."""


MAX_UNITS = 10_000
"""The most units one sweep runs (each a whole calibration: minutes on a core, so 10,000 is
weeks of a machine), checked before the grid is built."""


@dataclass(frozen=True)
class Unit:
    """One calibration run of a sweep: an instrument and a seed.

    Attributes:
        bias_seed: which instrument (the draw of its cable bias).
        seed: seeds Phase I, the DNN, Phase II, the forests and the benchmark.
    """

    bias_seed: int
    seed: int

    @property
    def name(self) -> str:
        """The unit's name, also its result file's stem: ``bias3-seed0``."""
        return f"bias{self.bias_seed}-seed{self.seed}"


@dataclass(frozen=True)
class SweepSettings:
    """What a sweep runs.

    Attributes:
        bias_seeds: the instruments, by bias seed (non-negative, no repeats).
        calibrators: the calibrators whose rows the table holds, of :data:`CALIBRATORS`.
            Every unit makes and benchmarks all three (one pipeline run makes them all),
            so choosing fewer changes the table, not the work.
        seeds: the run seeds (non-negative, no repeats).
        pipeline: the budget and world every unit shares (Phase I trajectories and poses,
            DNN epochs, bias preset, camera resolution); its ``bias_seed`` and ``seed`` are
            replaced by each unit's.

    Raises:
        ValueError: seeds that are not distinct non-negative ints, more than
            :data:`MAX_UNITS` units, or unknown or repeated calibrators.
    """

    bias_seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    calibrators: tuple[str, ...] = CALIBRATORS
    seeds: tuple[int, ...] = (0,)
    pipeline: PipelineConfig = PipelineConfig()

    def __post_init__(self) -> None:
        if isinstance(self.calibrators, str):  # its letters would be taken as names
            raise ValueError(f"calibrators must be a sequence of names of {list(CALIBRATORS)}, got the string {self.calibrators!r}")
        object.__setattr__(self, "calibrators", tuple(self.calibrators))
        for field in ("bias_seeds", "seeds"):
            object.__setattr__(self, field, _as_ints(getattr(self, field), field))
        _check_seeds(self.bias_seeds, "bias_seeds")
        _check_seeds(self.seeds, "seeds")
        if len(self.bias_seeds) * len(self.seeds) > MAX_UNITS:
            raise ValueError(
                f"{len(self.bias_seeds):,} instruments x {len(self.seeds):,} seeds is {len(self.bias_seeds) * len(self.seeds):,} units; "
                f"a sweep runs at most {MAX_UNITS:,} (each a calibration of minutes): split it into several sweeps"
            )
        if not self.calibrators:
            raise ValueError(f"calibrators is empty; expected some of {list(CALIBRATORS)}")
        unknown = [name for name in self.calibrators if name not in CALIBRATORS]
        if unknown:
            raise ValueError(f"unknown calibrators {unknown}; expected some of {list(CALIBRATORS)}")
        _check_unique(self.calibrators, "calibrators")
        if not isinstance(self.pipeline, PipelineConfig):  # which checks its own budget and world when made
            raise ValueError(f"pipeline must be a PipelineConfig, got {type(self.pipeline).__name__}")

    def units(self) -> list[Unit]:
        """The units, instruments first then seeds, in the order given."""
        return [Unit(bias_seed=bias_seed, seed=seed) for bias_seed in self.bias_seeds for seed in self.seeds]

    def unit_config(self, unit: Unit) -> PipelineConfig:
        """The calibration pipeline's settings for one unit."""
        return dataclasses.replace(self.pipeline, bias_seed=unit.bias_seed, seed=unit.seed)

    def stamp(self) -> dict[str, Any]:
        """What a unit's numbers depend on besides its instrument and seed: the settings an
        output folder is stamped with. The grid is not in it, so a sweep can grow (more
        instruments, seeds or calibrators) in the same folder and reuse its finished units."""
        shared = dataclasses.asdict(self.pipeline)
        del shared["bias_seed"], shared["seed"]
        return {"pipeline": shared}


def _check_unique(values: tuple[Any, ...], name: str) -> None:
    counts = collections.Counter(values)  # one pass, not quadratic
    repeated = sorted((value for value, count in counts.items() if count > 1), key=str)
    if repeated:
        raise ValueError(f"{name} repeats {repeated}; give each once")


def _as_ints(values: Any, name: str) -> tuple[int, ...]:
    """Integers (numpy's too) as a tuple of ``int``; at most :data:`MAX_UNITS` of them."""
    try:
        values = list(itertools.islice(values, MAX_UNITS + 1))  # a huge range is not listed whole
    except TypeError:
        raise ValueError(f"{name} is {values!r}; expected non-negative integers") from None
    if len(values) > MAX_UNITS:
        raise ValueError(f"{name} has more than {MAX_UNITS:,} values; a sweep runs at most {MAX_UNITS:,} units")
    try:
        if any(isinstance(value, bool) for value in values):
            raise TypeError(name)
        return tuple(operator.index(value) for value in values)
    except TypeError:
        raise ValueError(f"{name} is {values!r}; expected non-negative integers") from None


MAX_SEED = 2**31 - 1
"""The largest instrument or seed a unit takes (:class:`~dvrk_gym.calibration.pipeline.PipelineConfig`'s)."""


def _check_seeds(values: tuple[int, ...], name: str) -> None:
    if not values:
        raise ValueError(f"{name} is empty; expected at least one non-negative integer")
    bad = [value for value in values if not 0 <= value <= MAX_SEED]
    if bad:
        raise ValueError(f"{name} has {bad}; expected non-negative integers up to {MAX_SEED}")
    _check_unique(values, name)


_NUMBER_OR_RANGE = re.compile(r"\s*(?P<first>[0-9]+)\s*(?:-\s*(?P<last>[0-9]+)\s*)?")
"""One part of a list of seeds: a non-negative integer, or an inclusive range of them ("7-9"), in ASCII
digits (``\\d`` would take other scripts' digits too, which ``int`` reads)."""


def parse_int_list(text: str, option: str) -> tuple[int, ...]:
    """Non-negative integers from a list of numbers and inclusive ranges: ``"0-4"``, ``"0,3,7-9"``.

    Args:
        text: the option's value.
        option: the option's name, for the error message.

    Raises:
        ValueError: not such a list, an empty range (``"4-0"``), a repeated number, or more
            than :data:`MAX_UNITS` numbers (refused before they are listed).
    """
    values: list[int] = []
    for part in text.split(","):
        match = _NUMBER_OR_RANGE.fullmatch(part)
        if match is None:
            raise ValueError(
                f"{option} {text!r}: {part.strip()!r} is not a non-negative number or a range of them; expected e.g. '0-4' or '0,3,7-9'"
            )
        first = int(match["first"])
        last = int(match["last"]) if match["last"] is not None else first
        if last < first:
            raise ValueError(f"{option} {text!r}: the range {part.strip()!r} is empty; write it low-high, e.g. '{last}-{first}'")
        if len(values) + last - first + 1 > MAX_UNITS:  # before the list is made: '0-100000000000' would fill the memory
            raise ValueError(f"{option} {text!r} lists more than {MAX_UNITS:,} numbers; a sweep runs at most {MAX_UNITS:,} units")
        values.extend(range(first, last + 1))
    _check_unique(tuple(values), option)
    return tuple(values)


def parse_calibrators(text: str) -> tuple[str, ...]:
    """Calibrator names from a comma-separated list (``"rbt,dnn,dnn+rf"``), checked.

    Raises:
        ValueError: an empty list, an unknown name or a repeated one.
    """
    names = tuple(part.strip().lower() for part in text.split(",") if part.strip())
    if not names:
        raise ValueError(f"--calibrators {text!r} names none; expected some of {','.join(CALIBRATORS)}")
    unknown = [name for name in names if name not in CALIBRATORS]
    if unknown:
        raise ValueError(f"--calibrators: unknown {unknown}; expected some of {','.join(CALIBRATORS)}")
    _check_unique(names, "--calibrators")
    return names
