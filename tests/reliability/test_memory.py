"""Memory stays flat over Debridement-v0 resets and env make/close cycles.

Before the fix every reset grew the process by 2.1 MB and every make/close cycle by 3.1 MB
(pybullet kept each list it was given as mesh data; benchmarks/bench_memory.py prints both).
"""

import gc

import gymnasium as gym
import psutil
import pytest

pytestmark = pytest.mark.slow


def _resident_mb() -> float:
    gc.collect()
    return psutil.Process().memory_info().rss / 1e6


def test_150_debridement_resets_grow_the_process_by_less_than_15_mb():
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=(320, 180))
    try:
        env.reset(seed=0)
        before = _resident_mb()
        for seed in range(1, 151):
            env.reset(seed=seed)
        growth = _resident_mb() - before
    finally:
        env.close()
    assert growth < 15.0, f"{growth:.1f} MB over 150 resets (2.1 MB each before the fix: 316 MB)"


def test_30_make_reset_close_cycles_grow_the_process_by_less_than_15_mb():
    def cycle(seed):
        env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=(320, 180))
        env.reset(seed=seed)
        env.close()

    cycle(0)
    before = _resident_mb()
    for seed in range(30):
        cycle(seed)
    growth = _resident_mb() - before
    assert growth < 15.0, f"{growth:.1f} MB over 30 cycles (3.1 MB each before the fix: 92 MB)"
