"""Time per frame of ``env.render()`` ("rgb_array"): PyBullet's EGL renderer against TinyRenderer.

Run: python benchmarks/bench_render.py  [--frames 8] [--env dvrk_gym/Debridement-v0] [--profile]

Prints, for 1920 x 1080 and 640 x 360 frames of the same scene in one process: the median
wall time and CPU time (all threads: llvmpipe draws on several) per frame with each
renderer, the first frame's time (EGL: the mirror client and shader compilation, and for
the process's first EGL env only, 1920 x 1080 as run here, the child process that tries the
plugin: the first-frame column is not like for like between the sizes), and TinyRenderer's
time over EGL's (their frames are timed one block after the other, not interleaved). Issue 18's targets: at most
0.3 s a 1920 x 1080 frame, at most 50 ms a 640 x 360 one. The detection images are not
timed here (they stay on TinyRenderer at ``camera_resolution``); the 640 x 360 frames come
from a 1920 x 1080 env through ``render_resolution``. Takes about a minute.

What the profiles found (``--profile`` shows cProfile's view of one TinyRenderer frame;
figures measured with the load average at 10-15 on the 2 cores):

* ``render()`` was TinyRenderer's ``getCameraImage`` and one numpy copy, nothing else (no
  post-processing, noise or stereo pair). The copy, dropping the alpha channel with a
  strided slice, took 55 ms at 1920 x 1080; OpenCV's ``cvtColor`` gives the same bytes in
  2 ms, and the perception images use it too. The rest, 0.73 s of CPU, is TinyRenderer
  shading what covers the frame (the tray, phantom and paper fill it). Issue 18's 2.7 s
  against 0.76 s was wall time against CPU time: on this machine under load, a frame's wall
  time is 2.4-3x its CPU time.
* TinyRenderer at 640 x 360 costs a tenth of 1920 x 1080: pixels, not triangles.
* The EGL plugin draws into a 1024 x 768 surface and stretches anything larger from it, so a
  1920 x 1080 frame is four 960 x 540 tiles. Each draw also renders the plugin's 4096 x 4096
  shadow map (it cannot be turned off): about 17 ms of CPU a draw, even at 16 x 16 pixels,
  so 70 of the 160 ms of a 1920 x 1080 frame. Fewer llvmpipe threads (LP_NUM_THREADS 0-2)
  change nothing.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import time

import gymnasium as gym

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym.cli.options import check_flag_bounds

RESOLUTIONS = ((1920, 1080), (640, 360))
TARGETS_S = {(1920, 1080): 0.3, (640, 360): 0.05}
RENDERERS = ("egl", "tiny")


def time_frames(env_id: str, resolution: tuple[int, int], renderer: str, frames: int) -> dict[str, float]:
    """Render ``frames`` frames after a first one; returns the first frame's time and the median wall and CPU time, s."""
    env = gym.make(env_id, render_mode="rgb_array", render_resolution=resolution, renderer=renderer)
    try:
        env.reset(seed=0)
        env.action_space.seed(0)  # the same pick, so every renderer and size draws the same scene
        env.step(env.action_space.sample())
        start = time.perf_counter()
        env.render()
        first = time.perf_counter() - start
        env.render()  # the EGL renderer's second draw still compiles shaders
        walls, cpus = [], []
        for _ in range(frames):
            wall, cpu = time.perf_counter(), time.process_time()
            frame = env.render()
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        assert frame.shape == (resolution[1], resolution[0], 3)
        return {"first": first, "wall": statistics.median(walls), "cpu": statistics.median(cpus)}
    finally:
        env.close()


def profile_tiny_frame(env_id: str) -> str:
    """cProfile's top entries for one 1920 x 1080 TinyRenderer frame."""
    env = gym.make(env_id, render_mode="rgb_array", renderer="tiny")
    try:
        env.reset(seed=0)
        env.render()
        profiler = cProfile.Profile()
        profiler.enable()
        env.render()
        profiler.disable()
    finally:
        env.close()
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(8)
    return out.getvalue()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=8, help="frames timed per renderer and size (default: %(default)s)")
    parser.add_argument("--env", default="dvrk_gym/Debridement-v0", help="env to render (default: %(default)s)")
    parser.add_argument("--profile", action="store_true", help="also print cProfile's view of one TinyRenderer frame")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"frames": (1, 10**4)})
    if args.env not in gym.registry or not args.env.startswith("dvrk_gym/"):
        parser.error(f"--env {args.env!r} is not one of {sorted(key for key in gym.registry if key.startswith('dvrk_gym/'))}")
    load_before = os.getloadavg()[0]
    results = {(res, r): time_frames(args.env, res, r, args.frames) for res in RESOLUTIONS for r in RENDERERS}
    load_after = os.getloadavg()[0]
    print(f"{args.env}, {args.frames} frames each; load average {load_before:.1f} before, {load_after:.1f} after ({os.cpu_count()} cores)")
    print(f"{'frame':<11} {'renderer':<9} {'wall ms':>9} {'CPU ms':>9} {'first s':>8} {'target ms':>10} {'met':>4}")
    for res in RESOLUTIONS:
        for renderer in RENDERERS:
            t = results[(res, renderer)]
            met = "yes" if t["wall"] <= TARGETS_S[res] else "no"
            label = f"{res[0]}x{res[1]}"
            wall, cpu, target = 1e3 * t["wall"], 1e3 * t["cpu"], 1e3 * TARGETS_S[res]
            print(f"{label:<11} {renderer:<9} {wall:>9.1f} {cpu:>9.1f} {t['first']:>8.2f} {target:>10.0f} {met:>4}")
    for res in RESOLUTIONS:
        tiny, egl = results[(res, "tiny")], results[(res, "egl")]
        print(f"TinyRenderer / EGL at {res[0]}x{res[1]}: {tiny['wall'] / egl['wall']:.1f}x wall, {tiny['cpu'] / egl['cpu']:.1f}x CPU")
    if args.profile:
        print(profile_tiny_frame(args.env))


if __name__ == "__main__":
    main()
