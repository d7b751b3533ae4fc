"""Memory over many Debridement-v0 resets and env make/close cycles (psutil's resident set size).

Run: python benchmarks/bench_memory.py  [--resets 1000] [--cycles 200] [--resolution 480 270]
Target (issue 17): flat. Before the fix each reset grew the process by about 2.1 MB
(pybullet kept every list passed to it as mesh data: the printed grid and the fragments'
ellipsoids and hulls, rebuilt at every reset); a make/close cycle by about 2.6 MB.
Takes about 2 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import gc
import time

import gymnasium as gym
import psutil

import dvrk_gym  # noqa: F401
from dvrk_gym.cli.options import check_flag_bounds

MB = 1e6


def resident_mb() -> float:
    """The process's resident set size, MB, after a garbage collection and (glibc) returning freed heap."""
    gc.collect()
    libc = ctypes.util.find_library("c")
    if libc and hasattr(ctypes.CDLL(libc), "malloc_trim"):
        ctypes.CDLL(libc).malloc_trim(0)
    return psutil.Process().memory_info().rss / MB


def resets(n: int, resolution: tuple[int, int], report_at: tuple[int, ...]) -> list[tuple[int, float, float]]:
    """(resets done, RSS growth MB, seconds) at each of ``report_at`` during ``n`` resets of one env."""
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=resolution)
    env.reset(seed=0)
    base, start, rows = resident_mb(), time.perf_counter(), []
    for i in range(1, n + 1):
        env.reset(seed=i)
        if i in report_at:
            rows.append((i, resident_mb() - base, time.perf_counter() - start))
    env.close()
    return rows


def cycles(n: int, resolution: tuple[int, int]) -> tuple[float, float]:
    """RSS growth, MB, over ``n`` make/reset/close cycles after a first one, and the seconds they took."""
    for _ in range(2):
        env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=resolution)
        env.reset(seed=0)
        env.close()
    base, start = resident_mb(), time.perf_counter()
    for i in range(n):
        env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=resolution)
        env.reset(seed=i)
        env.close()
    return resident_mb() - base, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resets", type=int, default=1000, help="resets of one Debridement-v0 env (default: %(default)s)")
    parser.add_argument("--cycles", type=int, default=200, help="make/reset/close cycles (default: %(default)s)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 270), metavar=("W", "H"), help="camera, pixels")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"resets": (1, 10**7), "cycles": (1, 10**6), "resolution": (None, None)})
    resolution = (args.resolution[0], args.resolution[1])
    marks = tuple(sorted({m for m in (50, 200, 500, args.resets) if m <= args.resets}))
    print(f"Debridement-v0 at {resolution[0]}x{resolution[1]}, RSS growth after the first reset:")
    for done, growth, seconds in resets(args.resets, resolution, marks):
        print(f"  {done:>5} resets: {growth:+7.1f} MB ({1e3 * growth / done:+.1f} kB per reset; {1e3 * seconds / done:.0f} ms per reset)")
    growth, seconds = cycles(args.cycles, resolution)
    print(
        f"  {args.cycles:>5} make/reset/close cycles: {growth:+7.1f} MB ({1e3 * growth / args.cycles:+.1f} kB per cycle; {seconds:.0f} s)"
    )


if __name__ == "__main__":
    main()
