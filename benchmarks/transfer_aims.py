"""Where trained GridTouch agents aim debridement picks, against where DNN+RF aims them.

A GridTouch-v0 agent learnt "camera-frame target -> base-frame command" on the 35 printed
circles; :func:`dvrk_gym.baselines.transfer.pick_policy` shows it a fragment's target
instead, as the calibrators are shown it. For the first pick of each of ``--trials`` seeded
trials (the same fragments for every policy), this prints how far each agent's command lies
from DNN+RF's: in the plane (median and largest, mm) and in height (mean and sd, mm; negative
is lower). DNN+RF's picks land on the fragments (*Debridement* in the README), so this
measures where an agent's misses come from. A few seconds per agent after the training:

    dvrk-gym reproduce --workers 2 --seed 0 --out RUN     # or dvrk-gym baseline train ... for each agent
    python benchmarks/transfer_aims.py --calibration RUN/calibration --agents RUN/baselines/sac_her/model.zip RUN/baselines/sac/model.zip
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym.baselines.checkpoints import load_agent
from dvrk_gym.baselines.transfer import pick_policy
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES


def aim_offsets(env: gym.Env, reference: CalibratedPolicy, policy: object, trials: int) -> np.ndarray:
    """(trials, 3) mm: ``policy``'s first command of each trial (seeds 0, 1, ...) minus ``reference``'s."""
    offsets = []
    for seed in range(trials):
        observation, _ = env.reset(seed=seed)
        ours = np.asarray(policy(observation), dtype=float)[:3]
        theirs = np.asarray(reference(observation), dtype=float)[:3]
        offsets.append(1e3 * (ours - theirs))
    return np.array(offsets)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calibration", type=Path, required=True, help="calibration run folder with DNN+RF (dvrk-gym calibrate)")
    parser.add_argument("--agents", type=Path, nargs="+", required=True, help="GridTouch agents' model.zip files (dvrk-gym baseline train)")
    parser.add_argument("--trials", type=int, default=12, help="seeded trials, the first pick of each (default: %(default)s)")
    parser.add_argument("--fragment", choices=sorted(FRAGMENT_TYPES), default="pumpkin_seed", help="fragment kind (default: %(default)s)")
    args = parser.parse_args()
    if args.trials < 1:
        parser.error(f"--trials must be at least 1, got {args.trials}")
    model, settings = load_calibrator(args.calibration, "dnn+rf")
    reference = CalibratedPolicy(model, target=fragment_target)
    world = {"bias": settings["bias"], "bias_seed": int(settings["bias_seed"])}
    env = gym.make("dvrk_gym/Debridement-v0", fragment=args.fragment, **world)
    try:
        print(f"first picks of {args.trials} trials ({args.fragment}, instrument {world}): the agent's command minus DNN+RF's")
        for path in args.agents:
            offsets = aim_offsets(env, reference, pick_policy(load_agent(path)), args.trials)
            plane = np.hypot(offsets[:, 0], offsets[:, 1])
            print(
                f"  {str(path):<50s} in the plane: median {np.median(plane):.2f} mm, largest {plane.max():.2f} mm;"
                f" height: mean {offsets[:, 2].mean():+.2f} mm, sd {offsets[:, 2].std():.2f} mm"
            )
    finally:
        env.close()


if __name__ == "__main__":
    main()
