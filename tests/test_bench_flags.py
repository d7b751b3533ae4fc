"""The benchmark scripts refuse flags they cannot run with, in one line and with status 2,
before any work: a zero or negative count printed figures of millions of steps per second
(bench_peers.py --steps -5) or failed with a traceback after minutes of work."""

import pytest
from benchmark_scripts import run_script, script_path

REFUSALS = [
    ("bench_peers", ["--steps", "0"], "--steps must be"),
    ("bench_peers", ["--steps", "-5", "--picks", "-5"], "--steps must be"),
    ("bench_peers", ["--rounds", "0"], "--rounds must be"),
    ("bench_peers", ["--resolution", "0", "0"], "--resolution"),
    ("bench_envs", ["--starts", "-7"], "--starts must be"),
    ("bench_envs", ["--trajectories", "0"], "--trajectories must be"),
    ("bench_memory", ["--cycles", "0"], "--cycles must be"),
    ("bench_memory", ["--resets", "-2"], "--resets must be"),
    ("bench_training_resume", ["--steps", "20", "--save-every", "100"], "never saves"),
    ("bench_training_resume", ["--save-every", "0"], "--save-every must be"),
    ("bench_sim", ["--n", "0"], "--n must be"),
    ("bench_render", ["--frames", "0"], "--frames must be"),
    ("bench_render", ["--env", "nope"], "is not one of ['dvrk_gym/"),
    ("bench_calibration", ["--trajectories", "0"], "--trajectories must be"),
    ("bench_sweep", ["--workers", "0"], "--workers must be"),
    ("bench_models", ["--folds", "0"], "--folds must be"),
    ("bench_faults", ["--workers", "0"], "--workers must be"),
    ("bench_fidelity", ["--workers", "0"], "--workers must be"),
    ("bench_fidelity", ["--seeds", "1", "1"], "--seeds must be at most 100 distinct"),
    ("bench_fidelity", ["--bias-seeds", "-1"], "--bias-seeds must be"),
    ("bench_fidelity", ["--resolution", "640", "480"], "--resolution"),
    ("bench_pick_parts", ["--trials", "0"], "--trials must be"),  # ZeroDivisionError at the end, after the picks
    ("bench_pick_parts", ["--fragment", "grape"], "invalid choice: 'grape'"),
    ("bench_forest", ["--rows", "0"], "--rows must be"),  # scikit-learn's error, after the fits
]


@pytest.mark.parametrize(("script", "flags", "message"), REFUSALS, ids=[f"{s} {' '.join(f)}" for s, f, _ in REFUSALS])
def test_a_benchmark_refuses_a_flag_it_cannot_run_with(script, flags, message):
    refused = run_script(script_path(script), *flags, timeout_s=60.0)  # a refusal that no longer refuses runs the benchmark
    assert refused.returncode == 2, (refused.stdout[-500:], refused.stderr[-500:])
    assert message in refused.stderr and "Traceback" not in refused.stderr
