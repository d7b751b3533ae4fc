"""Throughput of the simulator core: kinematics, marker detection on pixels, rendering.

Run: python benchmarks/bench_sim.py  (prints a table; targets from issue 2: at least 150
stereo marker detections per second on one core at 1920 x 1080 pixel density).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.envs.exploration import sample_paper_poses
from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.ik import inverse_kinematics
from dvrk_gym.sim.world import DvrkWorld, WorldConfig


def _rate(fn, n: int) -> float:
    start = time.perf_counter()
    for i in range(n):
        fn(i)
    return n / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=400, help="marker detections to time (default: %(default)s)")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"n": (1, 10**6)})
    rng = np.random.default_rng(0)
    poses = sample_paper_poses(rng, args.n)
    joints = [inverse_kinematics(p) for p in poses]

    fk = _rate(lambda i: kin.forward_kinematics(joints[i % len(joints)]), 20000)
    ik = _rate(lambda i: inverse_kinematics(poses[i % len(poses)]), 20000)

    world = DvrkWorld(WorldConfig(bias="paper"))
    seen = 0
    detect_times = []
    for pose in poses:
        world.move_to(pose)
        start = time.perf_counter()
        seen += world.observe_marker().seen_both
        detect_times.append(time.perf_counter() - start)
    move = _rate(lambda i: world.move_to(poses[i % len(poses)]), 1000)
    full_hd = [_time(lambda: world.render("left")) for _ in range(5)]
    world.close()

    small = DvrkWorld(WorldConfig(bias="paper", camera_resolution=(640, 360)))
    small_times = [_time(lambda: small.render("left")) for _ in range(20)]
    small.close()

    print(f"{'figure':<58} {'value':>12}")
    print(f"{'forward kinematics, calls/s':<58} {fk:>12,.0f}")
    print(f"{'inverse kinematics, calls/s':<58} {ik:>12,.0f}")
    print(f"{'move_to (IK + cable model + body update), calls/s':<58} {move:>12,.0f}")
    label = f"stereo marker detections/s at {PAPER_INTRINSICS.width}x{PAPER_INTRINSICS.height} (pixel path)"
    print(f"{label:<58} {1.0 / statistics.mean(detect_times):>12,.1f}")
    print(f"{'  of which seen by both cameras':<58} {seen / len(poses):>12.0%}")
    print(f"{'full-frame render 640x360, ms (median)':<58} {1e3 * statistics.median(small_times):>12.1f}")
    print(f"{'full-frame render 1920x1080, ms (median)':<58} {1e3 * statistics.median(full_hd):>12.1f}")


def _time(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
