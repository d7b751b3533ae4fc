"""How deep a calibrator's debridement picks go under the paper, and how far that slides the jaws.

A pick aims its command at the fragment the endoscope sees, then lowers the open jaws
``grip_depth_m`` (2 mm, the authors' ``--z_offset``) under that target onto a floor just over
the paper; Debridement-v0's compliant paper slides jaws sent under the paper as GridTouch-v0's
touches slide (:mod:`dvrk_gym.sim.table.contact`). For the first pick of each of ``--trials``
seeded trials (the same fragments for every calibrator), this prints the medians, in mm, of:

- ``seen``: the height over the paper of the point the endoscope triangulated (its top, about);
- ``centre``: the true height of that fragment's centre over the paper;
- ``aimed``: where the calibrator's command puts the closed jaw tip (the instrument's true
  kinematics, no floor), height over the paper;
- ``+2 mm seen``: how far the aimed height moves when the seen point is raised 2 mm (the
  base frame's z): 2 for a map that follows height, 0 for one that puts every point on the
  paper;
- ``under paper``: how far the pick's lowered command sends the closed jaw tip under the
  paper (predicted from the cable state at the trial's start), and ``slide``: how far the
  env's paper then slides the jaws (none on a rigid one).

Evaluation only (it reads the simulator's truth). A few seconds per calibrator::

    dvrk-gym calibrate --out DIR
    python benchmarks/pick_depths.py --calibration DIR
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
from fidelity_table_runs import read_calibration

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym import paper
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.policy import calibrator_input
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES

PAPER_Z_M = float(WORKSPACE_CENTER_M[2])
RAISE_M = 0.002
"""How far the seen point is raised to measure how the map follows height, metres."""


def aimed_tip(env: gym.Env, command: np.ndarray) -> np.ndarray:
    """Where ``command`` (bx, by, bz, yaw) puts the closed jaw tip, (3,) m, with the
    instrument's true kinematics from its present cable state (left as it was)."""
    world = env.unwrapped.world
    q, _ = ik.inverse_kinematics_clamped(tool_pose(command[:3], float(command[3])), q_ref=world.q_cmd)
    state = world.cable.get_state()
    try:
        return kin.touch_point(world.cable.true_joints(q), world.cable.true_dh)
    finally:
        world.cable.set_state(state)


def first_picks(env: gym.Env, calibrator: object, trials: int) -> np.ndarray:
    """(trials, 6) mm per first pick: seen, centre, aimed, aimed change for the raised seen
    point, depth under the paper, slide (see the module)."""
    camera = env.unwrapped.world.camera
    grip_depth = env.unwrapped.config.timing.grip_depth_m
    rows = []
    for seed in range(trials):
        observation, _ = env.reset(seed=seed)
        seen_cam, yaw = fragment_target(observation)
        seen = camera.to_world(np.asarray(seen_cam)[None])[0]
        raised_cam = camera.to_camera_frame((seen + [0.0, 0.0, RAISE_M])[None])[0]
        aims = [calibrator.predict(calibrator_input(point, yaw))[0] for point in (seen_cam, raised_cam)]
        tips = [aimed_tip(env, np.array([*aim, kin.nearest_paper_yaw(yaw)])) for aim in aims]
        centres = env.unwrapped.table.true_fragment_positions()
        centre = centres[np.argmin(np.linalg.norm(centres[:, :2] - seen[:2], axis=1))]
        under = PAPER_Z_M - (tips[0][2] - grip_depth)
        slide = float(np.linalg.norm(env.unwrapped.table.contact.slide_m(under)))
        rows.append([seen[2] - PAPER_Z_M, centre[2] - PAPER_Z_M, tips[0][2] - PAPER_Z_M, tips[1][2] - tips[0][2], max(under, 0.0), slide])
    return 1e3 * np.array(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calibration", type=Path, required=True, help="calibration run folder (dvrk-gym calibrate)")
    parser.add_argument("--calibrators", nargs="+", default=["dnn", "dnn+rf"], choices=sorted(paper.METHOD_LABELS))
    parser.add_argument("--trials", type=int, default=12, help="seeded trials, the first pick of each (default: %(default)s)")
    args = parser.parse_args()
    if not 1 <= args.trials <= 1000:
        parser.error(f"--trials must be in [1, 1000], got {args.trials}")
    print(f"first picks of {args.trials} trials; medians, mm: heights over the paper, depth under it, slide")
    print(f"{'fragment':<14}{'calibrator':<10}{'seen':>8}{'centre':>8}{'aimed':>8}{'+2 mm seen':>12}{'under paper':>13}{'slide':>8}")
    world = read_calibration(parser, args.calibration).env_kwargs()
    calibrators = {name: load_calibrator(args.calibration, name)[0] for name in args.calibrators}
    for fragment in sorted(FRAGMENT_TYPES):
        for name, calibrator in calibrators.items():
            env = gym.make("dvrk_gym/Debridement-v0", fragment=fragment, **world)
            try:
                seen, centre, aimed, follows, under, slide = np.median(first_picks(env, calibrator, args.trials), axis=0)
            finally:
                env.close()
            label = paper.METHOD_LABELS[name]
            print(
                f"{fragment:<14}{label:<10}{seen:>8.2f}{centre:>8.2f}{aimed:>8.2f}{follows:>12.2f}{under:>13.2f}{slide:>8.2f}", flush=True
            )


if __name__ == "__main__":
    main()
