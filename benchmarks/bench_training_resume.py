"""What saving a training's state costs, and random SIGKILLs of ``dvrk-gym baseline train``, each resumed.

Run: python benchmarks/bench_training_resume.py  [--steps 1000] [--save-every 100] [--kills 5] [--kill-steps 300] [--seed 0]

Part 1, the cost: after a short warm-up training (imports, compiled kernels), the same
training (``sac_her``, the agent's own settings, 320 x 180 images) run twice in this
process, without saves and saving its state every
``--save-every`` env steps; prints both wall times and their ratio, the saves' count, mean
time and size, the time to resume from the last save, and whether the two models have the
same weights (they must: saving changes nothing).

Part 2, the kills: an uninterrupted ``dvrk-gym baseline train --steps KILL_STEPS`` is timed
and kept as the reference; then, ``--kills`` times, the same command (saving every
``--save-every`` / 10 env steps) is started in its own folder and killed with SIGKILL at a
random moment within the reference's wall time, and run again to the end. Each resume must
finish, leave no training state and no temporary file, and write a model whose weights and
learning curve equal the reference's (a run killed after it had written every output and
deleted its state is reported by the rerun as a finished training, not trained again, and
its outputs are checked instead). Prints one line per kill (whether a training state,
and whether the model, had been saved when it was killed: the state is deleted only once
every output is written, so a run killed after saving its model resumes from its last save
too) and the counts.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import dvrk_gym.baselines.resume.writer as writer
from dvrk_gym.baselines import TrainConfig, load_agent, train
from dvrk_gym.baselines.resume import STATE_FILE_NAME
from dvrk_gym.cli.options import check_flag_bounds

RESOLUTION = (320, 180)


def same_weights(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    first, second = a.state_dict(), b.state_dict()
    return first.keys() == second.keys() and all(torch.equal(first[key], second[key]) for key in first)


def cost(steps: int, save_every: int, seed: int, folder: Path) -> None:
    """Part 1: one training without saves and one with, side by side in time."""
    config = TrainConfig(agent="sac_her", steps=steps, seed=seed, camera_resolution=RESOLUTION, eval_points=1)
    train(dataclasses.replace(config, steps=20, overrides={"learning_starts": 10}), progress=False)  # warm-up: imports, compiled kernels
    start = time.perf_counter()
    plain = train(config, progress=False)
    plain_s = time.perf_counter() - start
    save_times: list[float] = []
    original = writer.save_training_state

    def timed(*args, **kwargs):
        begin = time.perf_counter()
        path = original(*args, **kwargs)
        save_times.append(time.perf_counter() - begin)
        return path

    writer.save_training_state = timed
    state = folder / STATE_FILE_NAME
    start = time.perf_counter()
    try:
        saving = train(config, progress=False, state_path=state, save_every=save_every)
    finally:
        writer.save_training_state = original
    saving_s = time.perf_counter() - start
    start = time.perf_counter()
    resumed = train(config, progress=False, state_path=state, save_every=10**9)
    resume_s = time.perf_counter() - start
    print(f"Saving the training state (sac_her, {steps} env steps, {RESOLUTION[0]}x{RESOLUTION[1]}, seed {seed})")
    print(f"  without saves {plain_s:.1f} s; saving every {save_every} steps {saving_s:.1f} s: ratio {saving_s / plain_s:.3f}")
    print(
        f"  {len(save_times)} saves, {np.mean(save_times) * 1e3:.0f} ms each (max {max(save_times) * 1e3:.0f}); "
        f"last file {state.stat().st_size / 1e6:.1f} MB"
    )
    print(f"  resuming from the last save and training the remaining steps: {resume_s:.1f} s")
    print(
        f"  same weights with and without saves: {same_weights(plain.model.policy, saving.model.policy)}; "
        f"resumed: {same_weights(plain.model.policy, resumed.model.policy)}"
    )
    print()


def command(out: Path, steps: int, save_every: int, seed: int) -> list[str]:
    return [sys.executable, "-m", "dvrk_gym.cli.main", "baseline", "train", "--steps", str(steps), "--seed", str(seed)] + [
        "--resolution",
        *map(str, RESOLUTION),
        "--eval-points",
        "5",
        "--save-every",
        str(save_every),
        "--out",
        str(out),
        "--no-progress",
    ]


def kills(n_kills: int, steps: int, save_every: int, seed: int, folder: Path) -> None:
    """Part 2: random SIGKILLs, each run again to the end, against an uninterrupted run."""
    reference = folder / "reference"
    start = time.perf_counter()
    subprocess.run(command(reference, steps, save_every, seed), check=True, capture_output=True)
    wall = time.perf_counter() - start
    expected = load_agent(reference / "model.zip").model.policy
    curve = json.loads((reference / "learning_curve.json").read_text())["points"]
    rng = np.random.default_rng(seed)
    print(f"SIGKILLs of dvrk-gym baseline train --steps {steps} --save-every {save_every} (reference {wall:.1f} s)")
    identical = leftovers = resumed_from_a_save = after_the_model = kept_finished = 0
    for kill in range(n_kills):
        out = folder / f"kill{kill}"
        after = float(rng.uniform(0.1, 0.95) * wall)
        process = subprocess.Popen(command(out, steps, save_every, seed), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(after)
        ended_first = process.poll() is not None
        process.send_signal(signal.SIGKILL)
        process.wait()
        had_state, had_model = (out / STATE_FILE_NAME).exists(), (out / "model.zip").exists()
        again = subprocess.run(command(out, steps, save_every, seed), capture_output=True, text=True)
        left = [p.name for p in out.rglob("*") if ".partial" in p.name or p.name == STATE_FILE_NAME] if out.exists() else []
        # Killed after every output was written (its state deleted), the rerun reports the finished
        # training and does not train again ("nothing to do"): the outputs it had written are checked.
        finished = again.returncode == 0 and "nothing to do" in again.stdout and had_model and not had_state
        kept_finished += finished
        same = (again.returncode == 0 or finished) and same_weights(expected, load_agent(out / "model.zip").model.policy)
        same = same and json.loads((out / "learning_curve.json").read_text())["points"] == curve
        identical += same
        leftovers += len(left)
        resumed_from_a_save += had_state
        after_the_model += had_model
        print(
            f"  kill {kill + 1}: at {after:.1f} s{' (had ended)' if ended_first else ''}, state: {had_state}, model: {had_model}, "
            f"rerun exit {again.returncode}, same model and curve: {same}, files left: {left or 'none'}",
            flush=True,
        )
    print(
        f"{identical}/{n_kills} identical to the uninterrupted run, {resumed_from_a_save} resumed from a saved state, "
        f"{after_the_model} after the model was saved, {kept_finished} after every output was written (kept, not trained again)"
    )
    print(f"{leftovers} files left (training states, temporary files)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=1000, help="env steps of part 1's trainings (default: %(default)s)")
    parser.add_argument(
        "--save-every",
        type=int,
        default=100,
        help="env steps between saves in part 1 (default: %(default)s; part 2 saves ten times as often)",
    )
    parser.add_argument("--kills", type=int, default=5, help="SIGKILLs in part 2 (default: %(default)s; 0 skips it)")
    parser.add_argument("--kill-steps", type=int, default=300, help="env steps of part 2's trainings (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    check_flag_bounds(
        parser, args, {"steps": (1, 10**7), "save_every": (1, None), "kills": (0, 1000), "kill_steps": (1, 10**7), "seed": (0, 2**31 - 1)}
    )
    if args.save_every > args.steps:
        parser.error(f"--save-every {args.save_every} is more than --steps {args.steps}: a training that never saves has nothing to time")
    folder = Path(tempfile.mkdtemp(prefix="bench_training_resume_"))
    try:
        cost(args.steps, args.save_every, args.seed, folder)
        if args.kills:
            kills(args.kills, args.kill_steps, max(1, args.save_every // 10), args.seed, folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
