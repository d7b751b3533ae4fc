"""Where a Debridement-v0 pick's wall time goes: timers around its parts, without a profiler.

Run: python benchmarks/bench_pick_parts.py  [--trials 4] [--resolution 1920 1080] [--fragment pumpkin_seed]

Steps ``--trials`` trials of eight seeded random picks (after one pick to warm up) with a
``time.perf_counter`` timer around each part below, and prints each part's milliseconds per
pick, its calls and its share of the picks' time in ``DebridementEnv._step_episode`` (the
resets' observations left out). The renders are both passes' (coarse and fine); the joints
are also set outside a physics step (``Gripper.place``: the free-space moves). cProfile's
per-call overhead swells the small Python functions of the physics loop about threefold;
these timers add a few microseconds a call. The parts nest (indented: inside the last part
one level up), so the shares do not add up. Issue 18's target is 10 picks/s, 100 ms a pick.

Two what-ifs measure how fast a pick would be if the simulation were changed, for a
decision on which numbers may change (each changes what is simulated or seen, so every
debridement table with it; neither is an option of the package):
``--what-if-physics-step S`` steps the physics every S seconds instead of 1/240 (the moves'
waypoints follow the step; what is counted in steps, the fragments' settling before a trial
and the jaws' still steps, then lasts longer in simulated time), and
``--what-if-coarse-only`` skips the full-resolution window around each fragment and takes
the coarse pass's blob (its centroid, ellipse angle and axes scaled to full resolution:
a quarter of the resolution).
"""

from __future__ import annotations

import argparse
import collections
import time
from typing import Any

import gymnasium as gym
import numpy as np

import dvrk_gym  # noqa: F401
from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.envs.debridement import DebridementEnv
from dvrk_gym.envs.picks import PickPrimitive
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.endoscope.fragment_detection import FragmentBlob, FragmentObserver
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot.body import PSMBody
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES
from dvrk_gym.sim.table.grasp import Gripper
from dvrk_gym.sim.table.table import DebridementTable

PARTS: tuple[tuple[int, type, str], ...] = (
    (0, DebridementEnv, "_step_episode"),
    (1, PickPrimitive, "run"),
    (2, DebridementTable, "move_stepped"),
    (3, DebridementTable, "_joint_path"),
    (3, Gripper, "follow"),
    (2, DebridementTable, "actuate_jaws"),
    (2, PickPrimitive, "drop_command"),
    (1, FragmentObserver, "observe"),
    (2, FragmentObserver, "_coarse_blobs"),
    (2, FragmentObserver, "_fine_blob"),
    (2, StereoCamera, "render"),
    (0, Gripper, "step"),
    (1, Physics, "step"),
    (0, PSMBody, "drive"),
)
"""(depth, class, method) of each timed part, in the order printed."""


def timed(seconds: dict[str, float], calls: collections.Counter, cls: type, name: str) -> None:
    """Replace ``cls.name`` with a wrapper that adds its wall time to ``seconds`` (this process only)."""
    original = getattr(cls, name)
    label = f"{cls.__name__}.{name}"

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            seconds[label] += time.perf_counter() - start
            calls[label] += 1

    setattr(cls, name, wrapper)


def what_if_physics_step(step_s: float) -> None:
    """Every physics world made after this steps every ``step_s`` seconds (this process only)."""
    original = Physics.__init__

    def init(self: Physics, gui: bool = False, time_step_s: float = step_s) -> None:
        original(self, gui=gui, time_step_s=step_s)

    Physics.__init__ = init  # type: ignore[method-assign]


def what_if_coarse_only() -> None:
    """Fragments are located by the coarse pass alone: each takes its coarse blob (centroid,
    ellipse angle and axes scaled to full resolution) instead of a full-resolution window's
    (this process only)."""
    coarse_blobs = FragmentObserver._coarse_blobs
    found: dict[int, FragmentBlob] = {}

    def remembered(self: FragmentObserver, client: Any, side: str) -> list[tuple[FragmentBlob, np.ndarray]]:
        blobs = coarse_blobs(self, client, side)
        for blob, box in blobs:
            centroid = (blob.centroid + 0.5) * self.scale - 0.5
            axes = (blob.axes_px[0] * self.scale, blob.axes_px[1] * self.scale)
            found[id(box)] = FragmentBlob(centroid, blob.angle_rad, axes, blob.area_px * self.scale**2, blob.touches_border)
        return blobs

    def coarse_blob(self: FragmentObserver, client: Any, side: str, box: np.ndarray, expected: np.ndarray) -> FragmentBlob:
        return found[id(box)]

    FragmentObserver._coarse_blobs = remembered  # type: ignore[method-assign]
    FragmentObserver._fine_blob = coarse_blob  # type: ignore[method-assign]


def add_what_if_arguments(parser: argparse.ArgumentParser) -> None:
    """The what-ifs' command-line flags (see the module notes)."""
    parser.add_argument("--what-if-physics-step", type=float, default=None, metavar="S", help="step the physics every S s (a what-if)")
    parser.add_argument("--what-if-coarse-only", action="store_true", help="no full-resolution windows (a what-if)")


def apply_what_ifs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> str:
    """Apply the what-ifs ``args`` asks for (this process only); what they are, for the output ("" for none)."""
    what_ifs = []
    if args.what_if_physics_step is not None:
        if not 0.0 < args.what_if_physics_step <= 0.05:
            parser.error("--what-if-physics-step must be in (0, 0.05] s")
        what_if_physics_step(args.what_if_physics_step)
        what_ifs.append(f"physics step {args.what_if_physics_step:g} s")
    if args.what_if_coarse_only:
        what_if_coarse_only()
        what_ifs.append("coarse pass only")
    return f"what-if, not the package's simulation: {', '.join(what_ifs)}" if what_ifs else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=4, help="trials of eight random picks (default: %(default)s)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"))
    parser.add_argument("--fragment", default="pumpkin_seed", choices=sorted(FRAGMENT_TYPES), help="(default: %(default)s)")
    add_what_if_arguments(parser)
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"trials": (1, 1000), "resolution": (None, None)})
    what_if = apply_what_ifs(parser, args)
    seconds: dict[str, float] = collections.defaultdict(float)
    calls: collections.Counter = collections.Counter()
    for _, cls, name in PARTS:
        timed(seconds, calls, cls, name)
    env = gym.make("dvrk_gym/Debridement-v0", fragment=args.fragment, max_picks=8, camera_resolution=tuple(args.resolution))
    env.reset(seed=1000)
    env.step(env.action_space.sample())  # warm-up: the first pick loads what later ones reuse
    env.action_space.seed(0)
    seconds.clear()
    calls.clear()
    picks, wall = 0, 0.0
    for trial in range(args.trials):
        before_seconds, before_calls = dict(seconds), calls.copy()
        env.reset(seed=trial)  # its observation is not a pick's: take it back out
        for label in list(seconds):
            seconds[label] = before_seconds.get(label, 0.0)
        calls.clear()
        calls.update(before_calls)
        start = time.perf_counter()
        for _ in range(8):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            picks += 1
            if terminated or truncated:
                break
        wall += time.perf_counter() - start
    env.close()
    steps = seconds["DebridementEnv._step_episode"]
    note = f" ({what_if})" if what_if else ""
    size = f"{args.resolution[0]} x {args.resolution[1]}"
    print(f"{picks} picks at {size}: {picks / wall:.2f} picks/s, {1e3 * wall / picks:.0f} ms a pick{note}")
    print(f"{'part (indented: inside the one above it)':<44} {'ms/pick':>8} {'calls':>7} {'share':>6}")
    for depth, cls, name in PARTS:
        label = f"{cls.__name__}.{name}"
        share = seconds[label] / steps if steps else np.nan
        print(f"{'  ' * depth + label:<44} {1e3 * seconds[label] / picks:>8.1f} {calls[label]:>7d} {share:>6.0%}")


if __name__ == "__main__":
    main()
