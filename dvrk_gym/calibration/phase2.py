"""Phase II: touch every circle for each of the five yaws and record a person's corrections.

For each yaw the robot goes to each of the 35 circle centres where the Phase I calibrator
sends it; a (simulated) person pushes the jaws onto the centre, and the change in the
robot's reported position is stored. The forests of the two-phase calibrator learn these
residuals.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

from dvrk_gym.calibration.policy import CalibratedPolicy, Calibrator, calibrator_input
from dvrk_gym.calibration.records import ArrayRecord, non_finite_rows
from dvrk_gym.envs.grid_touch import N_CIRCLES, TOUR
from dvrk_gym.sim.robot.kinematics import PAPER_YAWS_RAD


@dataclass(frozen=True)
class Phase2Data(ArrayRecord):
    """Phase II corrections, one row per touch (SI units).

    Attributes:
        camera_position: (N, 3) the circle centre as the endoscope saw it, m.
        orientation: (N, 3) the (yaw, pitch, roll) used, rad.
        commanded: (N, 3) where the calibrator sent the robot (base frame), m.
        corrected: (N, 3) the reported position after the person's correction, m.
        circle: (N,) which circle.
    """

    camera_position: np.ndarray
    orientation: np.ndarray
    commanded: np.ndarray
    corrected: np.ndarray
    circle: np.ndarray
    ROW_LAYOUT = {
        "camera_position": ((3,), "f"),
        "orientation": ((3,), "f"),
        "commanded": ((3,), "f"),
        "corrected": ((3,), "f"),
        "circle": ((), "iu"),
    }

    @classmethod
    def value_problem(cls, data: dict[str, np.ndarray]) -> str | None:
        """A position or orientation that is not finite (every touch saw its circle and was corrected)."""
        problems = (non_finite_rows(name, data[name]) for name in ("camera_position", "orientation", "commanded", "corrected"))
        return next((problem for problem in problems if problem is not None), None)

    @property
    def X(self) -> np.ndarray:
        """Calibrator inputs (N, 6): camera position (m), yaw, pitch, roll (rad)."""
        return np.hstack([self.camera_position, self.orientation])

    @property
    def in_authors_tour(self) -> bool:
        """Whether each yaw's 35 touches went in the authors' order (:data:`~dvrk_gym.envs.grid_touch.TOUR`),
        as :func:`collect_phase2` touches them (a Phase II made before it took their tour went row-major)."""
        circles = np.asarray(self.circle)
        return len(circles) > 0 and len(circles) % N_CIRCLES == 0 and bool((circles.reshape(-1, N_CIRCLES) == TOUR).all())


def collect_phase2(
    env: gym.Env, calibrator: Calibrator, yaws: np.ndarray = PAPER_YAWS_RAD, seed: int = 0, *, progress: bool = True
) -> Phase2Data:
    """Run the paper's Phase II on GridTouch-v0: every yaw, every circle (in the authors' order,
    :data:`~dvrk_gym.envs.grid_touch.TOUR`), one correction each.

    Args:
        env: a GridTouch-v0 environment (wrapped or not).
        calibrator: the Phase I calibrator that chooses where to send the robot.
        yaws: the yaws to use, rad (the paper's five by default).
        seed: seeds the first reset; the rest of the pass follows deterministically.
        progress: show a progress bar.
    """
    policy = CalibratedPolicy(calibrator)
    rows: dict[str, list] = {f.name: [] for f in fields(Phase2Data)}
    env.reset(seed=seed)
    with tqdm(total=len(yaws) * N_CIRCLES, desc="Phase II touches", disable=not progress) as bar:
        for yaw in yaws:
            for circle in TOUR:  # the authors' order: the cables' history carries from circle to circle
                observation, _ = env.reset(options={"yaw": float(yaw), "circle": circle})
                action = policy(observation)
                _, _, _, _, info = env.step(action)
                rows["camera_position"].append(np.asarray(observation["desired_goal"], dtype=float))
                rows["orientation"].append(calibrator_input(observation["desired_goal"], float(yaw))[0, 3:])
                rows["commanded"].append(action[:3].astype(float))
                rows["corrected"].append(info["reported_position"] + info["human_correction"])
                rows["circle"].append(circle)
                bar.update()
    return Phase2Data(**{name: np.array(values) for name, values in rows.items()})
