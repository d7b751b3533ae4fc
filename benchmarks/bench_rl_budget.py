"""Plain stable-baselines3 on the raw envs, and through each of the package's wrappers: the budget each needs.

Run: python benchmarks/bench_rl_budget.py [--variants raw wrap_grid_touch ...] [--seeds 0 1 2]
         [--steps 5000] [--every 500] [--workers 2] [--out dvrk_gym_out/rl_budget]
     python benchmarks/bench_rl_budget.py --env debridement [--steps 1000] [--every 250] [--trials 2]

The agent is what a user who knows SB3 writes first, with SB3's defaults for everything
else (learning rate 3e-4, 100 random steps, one gradient update per step, 256 x 256 nets)::

    SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, seed=seed)   # GridTouch-v0
    SAC("MultiInputPolicy", env, seed=seed)                                        # Debridement-v0

It learns ``gym.make(...)`` with no keyword (``raw``), or the same env through one of the
package's wrappers (:data:`VARIANTS` says what each changes), or through all of them as the
package's own agents see it (``wrap_grid_touch``, ``wrap_debridement``). These are not the
package's agents (``dvrk-gym baseline``: 4 updates per step, learning rate 1e-3).

At step 0 and every ``--every`` training steps the deterministic policy is evaluated on a
separate env, the same episodes every time (reset seed :data:`EVAL_SEED`). GridTouch-v0: the
35 circles at yaw 0 (the env's default yaw, the only one a raw agent trains at) and the 35
circles with the yaw cycling through the calibration benchmark's six settings (the package's
learning-curve evaluation): mean touch error (mm), success (within 1 mm) and, for an agent
that chooses its own yaw, how far its yaw is from the one the episode asks for (degrees).
Debridement-v0: ``--trials`` trials of eight picks: success rate and mean true grip offset.

Each run (variant, seed) is written to ``--out/runs/`` as it finishes and reused by the next
call with the same settings, so an interrupted benchmark resumes and a later call can add
seeds or variants: a call trains the ``--variants`` x ``--seeds`` not yet there, then prints
the tables and writes ``--csv`` (every point) and ``--figure`` (mean over seeds against
training steps, the range shaded) for every run in ``--out`` with the same ``--env``,
``--steps``, ``--every`` and ``--trials``. Torch runs on one thread per run.

Duration, two runs side by side on a quiet 2-core machine: a GridTouch run of 5,000 steps
98-108 s of training (46-51 steps/s) and a few seconds of evaluations, so the default 6
variants x 3 seeds about 16 minutes (7-17 minutes a run when other jobs shared the cores);
a Debridement run of 2,000 picks about 10 minutes (3.1-3.2 picks/s) and 15-30 s per
evaluation of two trials.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import RescaleAction

from dvrk_gym import paper
from dvrk_gym.baselines.picking import wrap_debridement
from dvrk_gym.baselines.wrappers import GoalScaling, TargetYawAction, TrainingYaws, wrap_grid_touch
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_json, atomic_write_text

EVAL_SEED = 10_000
"""Reset seed of every evaluation: the same episodes at every checkpoint, in every run."""
N_CIRCLES = 35
ENV_IDS = {"grid_touch": "dvrk_gym/GridTouch-v0", "debridement": "dvrk_gym/Debridement-v0"}
SIX_SETTINGS = (-np.pi / 2, -np.pi / 4, 0.0, np.pi / 4, np.pi / 2, "random")
"""The calibration benchmark's yaw settings (rad, or a random yaw per circle)."""


class CommandedYaw(gym.Wrapper):
    """Records, for each step of the raw env, |commanded yaw - the yaw the episode asks for| (rad)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.yaw_errors_rad: list[float] = []

    def step(self, action: Any) -> Any:
        result = self.env.step(action)
        self.yaw_errors_rad.append(abs(float(np.asarray(action)[3]) - float(result[4]["target_yaw"])))
        return result


class Deliveries(gym.Wrapper):
    """Records which steps (1-based) of the raw Debridement-v0 delivered a fragment (reward > 0)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.steps = 0
        self.delivered_steps: list[int] = []

    def step(self, action: Any) -> Any:
        result = self.env.step(action)
        self.steps += 1
        if float(result[1]) > 0:
            self.delivered_steps.append(self.steps)
        return result


def _unit_box(env: gym.Env) -> gym.Env:
    unit = np.ones(env.action_space.shape, dtype=np.float32)
    return RescaleAction(env, min_action=-unit, max_action=unit)


VARIANTS: dict[str, dict[str, tuple[str, Callable[[gym.Env, bool], gym.Env]]]] = {
    "grid_touch": {
        "raw": ("gym.make alone: goals in camera-frame metres, action (bx, by, bz, yaw) in its box", lambda env, training: env),
        "GoalScaling": ("goals scaled from metres to about [-1, 1] over the phantom", lambda env, training: GoalScaling(env)),
        "TargetYawAction": ("action (bx, by, bz): the yaw is the one the episode asks for", lambda env, training: TargetYawAction(env)),
        "RescaleAction": ("action (bx, by, bz, yaw) in [-1, 1] (gymnasium's RescaleAction)", lambda env, training: _unit_box(env)),
        "TrainingYaws": (
            "training episodes tour the 35 circles at each paper yaw in turn (raw: yaw 0 always)",
            lambda env, training: TrainingYaws(env, "paper") if training else env,
        ),
        "wrap_grid_touch": (
            "all four: the package's agents' view (wrap_grid_touch(env, training_yaws='paper'))",
            lambda env, training: wrap_grid_touch(env, "paper" if training else None),
        ),
    },
    "debridement": {
        "raw": ("gym.make alone: 1 per delivered fragment; action (bx, by, bz, yaw) in its box", lambda env, training: env),
        "wrap_debridement": (
            "the pick agent's view: the pick target only, (bx, by, bz) in [-1, 1], a shaped reward",
            lambda env, training: wrap_debridement(env),
        ),
    },
}
"""Per env, each variant's description and how it wraps the raw env (``training``: the training env)."""


def build_env(env_name: str, variant: str, training: bool) -> tuple[gym.Env, Any]:
    """The env as the agent sees it, and the recorder under its wrappers (:class:`CommandedYaw` or :class:`Deliveries`)."""
    recorder = (CommandedYaw if env_name == "grid_touch" else Deliveries)(gym.make(ENV_IDS[env_name]))
    return VARIANTS[env_name][variant][1](recorder, training), recorder


def evaluate_grid_touch(model: Any, env: gym.Env, recorder: CommandedYaw) -> dict[str, float]:
    """Touch error (mm), success and yaw error (deg) over the 35 circles, at yaw 0 and in the six settings."""
    from dvrk_gym.envs.grid_touch import TOUR
    from dvrk_gym.evaluation.episodes import run_episodes

    sets: dict[str, Callable[[int], dict[str, Any]]] = {  # the circles in the authors' order, as the benchmark touches them
        "yaw0": lambda i: {"circle": TOUR[i], "yaw": 0.0},
        "six": lambda i: {"circle": TOUR[i], "yaw": SIX_SETTINGS[i % len(SIX_SETTINGS)]},
    }
    row: dict[str, float] = {}
    for name, options in sets.items():
        recorder.yaw_errors_rad.clear()
        results = run_episodes(env, model, n_episodes=N_CIRCLES, seed=EVAL_SEED, options=options, progress=False)
        row[f"{name}_mm"] = float(np.mean([r.metrics["mm_error"] for r in results]))
        row[f"{name}_success"] = float(np.mean([r.metrics["is_success"] for r in results]))
        row[f"{name}_yaw_error_deg"] = float(np.degrees(np.mean(recorder.yaw_errors_rad)))
    return row


def evaluate_debridement(model: Any, env: gym.Env, trials: int) -> dict[str, float]:
    """Success rate and mean true grip offset (mm) over ``trials`` trials of eight picks."""
    from dvrk_gym.baselines.curves import evaluate_pick_curve_point

    point = evaluate_pick_curve_point(model, env, 0, EVAL_SEED, n_trials=trials)
    return {"success": point.success_rate, "grip_offset_mm": point.mm_error}


def run_one(env_name: str, variant: str, seed: int, steps: int, every: int, trials: int) -> dict[str, Any]:
    """Train one plain SAC agent and evaluate it at step 0 and every ``every`` steps."""
    from stable_baselines3 import SAC, HerReplayBuffer
    from stable_baselines3.common.callbacks import BaseCallback

    from dvrk_gym.baselines.agents import silent_logger
    from dvrk_gym.utils.torch_threads import torch_threads

    train_env, deliveries = build_env(env_name, variant, training=True)
    eval_env, recorder = build_env(env_name, variant, training=False)
    points: list[dict[str, float]] = []
    clock = {"eval": 0.0}

    def evaluate(model: Any) -> None:
        start = time.perf_counter()
        grid_touch = env_name == "grid_touch"
        row = evaluate_grid_touch(model, eval_env, recorder) if grid_touch else evaluate_debridement(model, eval_env, trials)
        points.append({"steps": int(model.num_timesteps), **row})
        clock["eval"] += time.perf_counter() - start

    class Checkpoints(BaseCallback):
        def _on_training_start(self) -> None:
            evaluate(self.model)

        def _on_step(self) -> bool:
            if self.num_timesteps % every == 0:
                evaluate(self.model)
            return True

    with torch_threads(1):
        her = {"replay_buffer_class": HerReplayBuffer} if env_name == "grid_touch" else {}
        model = SAC("MultiInputPolicy", train_env, seed=seed, device="cpu", **her)
        model.set_logger(silent_logger())  # writes nothing; learning is unchanged
        start = time.perf_counter()
        model.learn(total_timesteps=steps, callback=Checkpoints())
        wall = time.perf_counter() - start
    train_env.close()
    eval_env.close()
    settings = {"env": env_name, "variant": variant, "seed": seed, "steps": steps, "every": every, "trials": trials}
    if env_name == "debridement":
        settings["train_delivered_steps"] = deliveries.delivered_steps
    return {**settings, "train_seconds": wall - clock["eval"], "eval_seconds": clock["eval"], "points": points}


def run_path(out: Path, env_name: str, variant: str, seed: int) -> Path:
    return out / "runs" / f"{env_name}_{variant}_seed{seed}.json"


def cached(path: Path, settings: dict[str, Any]) -> dict[str, Any] | None:
    """A finished run with the same settings, or None."""
    if not path.is_file():
        return None
    run = json.loads(path.read_text())
    return run if all(run.get(key) == value for key, value in settings.items()) else None


def settings_of(args: argparse.Namespace, variant: str, seed: int) -> dict[str, Any]:
    return {"env": args.env, "variant": variant, "seed": seed, "steps": args.steps, "every": args.every, "trials": args.trials}


def train_missing(args: argparse.Namespace) -> None:
    """Train every (variant, seed) asked for that has no cached run, on ``args.workers`` processes."""
    todo = [
        settings_of(args, v, seed)
        for seed in args.seeds
        for v in args.variants
        if not cached(run_path(args.out, args.env, v, seed), settings_of(args, v, seed))
    ]
    (args.out / "runs").mkdir(parents=True, exist_ok=True)
    print(f"{len(args.seeds) * len(args.variants) - len(todo)} runs cached, {len(todo)} to train on {args.workers} worker(s)", flush=True)
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run_one, s["env"], s["variant"], s["seed"], s["steps"], s["every"], s["trials"]) for s in todo]
        for future in as_completed(futures):
            run = future.result()
            atomic_write_json(run_path(args.out, run["env"], run["variant"], run["seed"]), run, indent=1)
            print(
                f"  {run['variant']} seed {run['seed']}: {run['train_seconds']:.0f} s training, {run['eval_seconds']:.0f} s evaluating",
                flush=True,
            )


def all_runs(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every run in ``--out`` of this env with the same steps, interval and trials (any variant, any seed), in VARIANTS order."""
    runs = []
    for variant in VARIANTS[args.env]:
        for path in sorted((args.out / "runs").glob(f"{args.env}_{variant}_seed*.json")):
            run = json.loads(path.read_text())
            if run["variant"] == variant and run == cached(path, settings_of(args, variant, run["seed"])):
                runs.append(run)
    return sorted(runs, key=lambda r: (list(VARIANTS[args.env]).index(r["variant"]), r["seed"]))


def metrics(env_name: str) -> list[tuple[str, str]]:
    """(column, label) of what the tables and the figure show."""
    if env_name == "grid_touch":
        return [("yaw0_mm", "touch error at yaw 0, mm"), ("six_mm", "touch error, six yaw settings, mm")]
    return [("success", "debridement success rate"), ("grip_offset_mm", "mean true grip offset, mm")]


def by_variant(runs: list[dict[str, Any]], column: str) -> dict[str, tuple[list[int], list[int], np.ndarray]]:
    """Per variant: its seeds, the checkpoints and a (seeds, checkpoints) array of ``column``."""
    table = {}
    for variant in dict.fromkeys(r["variant"] for r in runs):
        chosen = [r for r in runs if r["variant"] == variant]
        steps = [p["steps"] for p in chosen[0]["points"]]
        table[variant] = ([r["seed"] for r in chosen], steps, np.array([[p[column] for p in r["points"]] for r in chosen]))
    return table


def print_tables(runs: list[dict[str, Any]], env_name: str) -> None:
    extra = [("six_success", "success (within 1 mm), six settings"), ("six_yaw_error_deg", "|yaw - the yaw asked for|, six settings, deg")]
    for column, label in metrics(env_name) + (extra if env_name == "grid_touch" else []):
        table = by_variant(runs, column)
        steps = next(iter(table.values()))[1]
        print(f"\n{label}: mean over seeds, against training steps; the seeds' range at the last step")
        print(f"{'variant':<17}{'seeds':<7}" + "".join(f"{s:>7}" for s in steps) + "   range")
        for variant, (seeds, _, values) in table.items():
            mean = values.mean(axis=0)
            seed_list = ",".join(map(str, seeds))
            print(
                f"{variant:<17}{seed_list:<7}"
                + "".join(f"{v:7.2f}" for v in mean)
                + f"   {values[:, -1].min():.2f}-{values[:, -1].max():.2f}"
            )
    for run in runs:
        if "train_delivered_steps" in run:
            delivered = run["train_delivered_steps"]
            first = f", the first at step {delivered[0]}" if delivered else ""
            print(f"{run['variant']} seed {run['seed']}: {len(delivered)} of {run['steps']} training picks delivered a fragment{first}")
    print("\nwall time per run: training without the evaluations, s; training steps/s")
    for run in runs:
        print(f"{run['variant']:<17} seed {run['seed']}: {run['train_seconds']:6.0f} s  {run['steps'] / run['train_seconds']:5.1f} steps/s")


def write_csv(runs: list[dict[str, Any]], path: Path) -> None:
    keys = [key for key in runs[0]["points"][0] if key != "steps"]
    lines = [",".join(["env", "variant", "seed", "steps", *keys])]
    for run in runs:
        for point in run["points"]:
            lines.append(",".join([run["env"], run["variant"], str(run["seed"]), str(point["steps"]), *(f"{point[k]:.6g}" for k in keys)]))
    atomic_write_text(path, "\n".join(lines) + "\n")


def plot(runs: list[dict[str, Any]], env_name: str, path: Path, command: str) -> None:
    """One panel per metric: mean over seeds against training steps, the seeds' range shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = metrics(env_name)
    fig, axes = plt.subplots(1, len(panels), figsize=(11, 4.4), sharey=env_name == "grid_touch")
    for ax, (column, label) in zip(axes, panels, strict=True):
        for variant, (seeds, steps, values) in by_variant(runs, column).items():
            style: dict[str, Any] = {"linewidth": 2.4} if variant in ("raw", "wrap_grid_touch", "wrap_debridement") else {"linewidth": 1.0}
            if variant == "RescaleAction":  # on top of raw's line: dashed, so that both show
                style.update(linestyle="--", linewidth=1.6)
            name = f"{variant} ({len(seeds)} seed{'s' if len(seeds) > 1 else ''})"
            (line,) = ax.plot(steps, values.mean(axis=0), marker="o", markersize=3, label=name, **style)
            ax.fill_between(steps, values.min(axis=0), values.max(axis=0), color=line.get_color(), alpha=0.12)
        if column.endswith("_mm") and env_name == "grid_touch":
            ax.axhline(paper.CALIBRATION_MEAN_MM["DNN+RF"], color="k", linestyle=":", linewidth=1, label="the paper's DNN+RF, 1.08 mm")
            ax.set_yscale("log")
        ax.set_xlabel("training steps (robot moves)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    agent = "SAC + HER" if env_name == "grid_touch" else "SAC"
    fig.suptitle(f"Plain SB3 {agent}, default settings, on {ENV_IDS[env_name]}: mean over seeds, range shaded\n{command}", fontsize=9)
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", choices=sorted(ENV_IDS), default="grid_touch")
    parser.add_argument("--variants", nargs="+", default=None, help="default: all of the env's (see VARIANTS)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="training seeds")
    parser.add_argument("--steps", type=int, default=None, help="training steps per run (default 5000; debridement 1000)")
    parser.add_argument("--every", type=int, default=None, help="steps between evaluations (default 500; debridement 250)")
    parser.add_argument("--trials", type=int, default=2, help="debridement: trials of eight picks per evaluation")
    parser.add_argument("--workers", type=int, default=2, help="runs side by side, one process each")
    parser.add_argument("--out", type=Path, default=Path("dvrk_gym_out/rl_budget"), help="the runs, cached (resumes)")
    parser.add_argument("--csv", type=Path, default=None, help="default: docs/rl_budget[_debridement].csv")
    parser.add_argument("--figure", type=Path, default=None, help="default: docs/rl_budget[_debridement].png")
    args = parser.parse_args()
    suffix = "" if args.env == "grid_touch" else "_debridement"
    args.variants = args.variants or list(VARIANTS[args.env])
    unknown = sorted(set(args.variants) - set(VARIANTS[args.env]))
    if unknown:
        parser.error(f"unknown variants {unknown} for --env {args.env}; valid: {list(VARIANTS[args.env])}")
    args.steps = args.steps or (5000 if args.env == "grid_touch" else 1000)
    args.every = args.every or (500 if args.env == "grid_touch" else 250)
    if args.steps < 1 or args.every < 1 or args.workers < 1 or args.trials < 1:
        parser.error("--steps, --every, --workers and --trials must be positive")
    for variant in args.variants:
        print(f"{variant:<17} {VARIANTS[args.env][variant][0]}")
    train_missing(args)
    runs = all_runs(args)
    print_tables(runs, args.env)
    csv_path = args.csv or Path(f"docs/rl_budget{suffix}.csv")
    figure = args.figure or Path(f"docs/rl_budget{suffix}.png")
    write_csv(runs, csv_path)
    command = f"python benchmarks/bench_rl_budget.py --env {args.env} --steps {args.steps} --every {args.every}" + (
        f" --trials {args.trials}" if suffix else ""
    )
    plot(runs, args.env, figure, command)
    print(f"\nwrote {csv_path} and {figure}")


if __name__ == "__main__":
    main()
