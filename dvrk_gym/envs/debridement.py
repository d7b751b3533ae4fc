"""Debridement-v0: pick eight fragments off the phantom and drop them in the receptacle.

The paper's experiment: eight pumpkin seeds or raisins lie at random on the paper; the
robot picks them one by one and drops them in a receptacle beside the phantom. Grasping
happens through contact only (:mod:`dvrk_gym.sim.table.grasp`), so the paper's failure modes
come out of the physics, and a judge (:mod:`dvrk_gym.sim.table.judge`) labels each
pick from the simulator's truth.

The env owns a world (the arm and the cameras) and the
:class:`~dvrk_gym.sim.table.table.DebridementTable` beside it (the fragments and the
gripper); every reset rebuilds both. Two action modes:

* ``"primitive"`` (default): one step is one pick at a base-frame target
  ``(bx, by, bz, yaw)`` (metres, radians): the commanded (reported) position that should
  put the closed jaw tip on the fragment, as GridTouch's and a calibrator's output. The
  pick (:mod:`dvrk_gym.envs.picks`) has the paper's six phases: to the fragment (free
  space), lower, grip, raise, to the receptacle, drop and rotate. The episode ends after
  ``max_picks`` picks or when no fragment is left on the paper.
  Lowered onto the paper, the jaws stall on a floor just above it; a command that goes
  on under the paper slides them along it as GridTouch's touches slide
  (``contact``, :mod:`dvrk_gym.sim.table.contact`; ``"rigid"`` stalls them in place), by
  as much as a GridTouch touch sent as deep; the reported pose does not show it.
* ``"delta"``: Cartesian and jaw increments at 10 Hz for learning agents,
  ``(dx, dy, dz, djaw)`` (metres and radians per step), physics stepped for the whole
  control period; truncated after ``max_steps``.

Observations hold only what the real robot has: its reported pose and jaw, and the
fragments the endoscope sees (:mod:`dvrk_gym.sim.endoscope.fragment_detection`). The truth is in
``info`` under ``true_*`` names.
"""

from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pybullet
from gymnasium import spaces

from dvrk_gym import paper
from dvrk_gym.envs.base import DvrkEnv, config_arguments, relax_option
from dvrk_gym.envs.debridement_config import (
    DEFAULT_PICK_TIMING,
    DELTA_ACTION_NAMES,
    DELTA_BOX_HIGH_M,
    DELTA_BOX_LOW_M,
    PICK_ACTION_NAMES,
    SERRATED_GRIPPER,
    DebridementConfig,
    PickTiming,
)
from dvrk_gym.envs.exploration import CAMERA_BOX_HIGH_M, CAMERA_BOX_LOW_M, encode_reported, reported_observation_space
from dvrk_gym.envs.grid_touch import ACTION_HIGH as PICK_HIGH
from dvrk_gym.envs.grid_touch import ACTION_LOW as PICK_LOW
from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.envs.picks import ABORTED_PICK_INFO, CLOSED_JAW_RAD, PHASES, PickPrimitive, PickRun
from dvrk_gym.sim.endoscope.fragment_detection import MAX_FRAGMENTS, FragmentDetection, FragmentObserver, check_fragment_camera
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.sim.table import judge
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT
from dvrk_gym.sim.table.grasp import GRASP_TIP_CLEARANCE_M
from dvrk_gym.sim.table.gripper_config import GripperConfig
from dvrk_gym.sim.table.table import DebridementTable

logger = logging.getLogger(__name__)

IMAGE_YAW_OFFSET_RAD = math.radians(7.0)
"""Tool yaw = IMAGE_YAW_OFFSET_RAD - image angle of the fragment's major axis (mod pi): the
endoscope looks down with image u along base -x, turned about 7 degrees. The jaws close
across a fragment whose length lies along the tool's yaw (measured here: mean 1.3, max
4.6 degrees off over the workspace, before the rounding to 45 degree steps)."""
NOTHING_SEEN_TARGET_M = np.array([0.0, 0.0, paper.ENDOSCOPE_HEIGHT_M])
"""Camera-frame target when no fragment is seen: the middle of the view, the endoscope's height away."""


def image_angle_to_yaw(angle_rad: float) -> float:
    """The tool yaw (rad, in [-pi/2, pi/2)) whose jaws close across a fragment whose major
    axis makes ``angle_rad`` with the left image's u axis."""
    return (IMAGE_YAW_OFFSET_RAD - angle_rad + math.pi / 2) % math.pi - math.pi / 2


def fragment_target(observation: dict[str, np.ndarray]) -> tuple[np.ndarray, float]:
    """Debridement's target for a CalibratedPolicy: the first fragment seen and its yaw.

    Returns:
        (camera-frame centre (3,) m, tool yaw rad); the middle of the view and yaw 0
        when nothing is seen.
    """
    seen = np.flatnonzero(np.asarray(observation["fragment_seen"]) > 0)
    if seen.size == 0:
        return NOTHING_SEEN_TARGET_M.copy(), 0.0
    i = int(seen[0])
    position = np.asarray(observation["fragment_positions"][i], dtype=float)
    angle = float(observation["fragment_angles"][i])
    if position.shape != (3,) or not (np.all(np.isfinite(position)) and math.isfinite(angle)):
        raise ValueError(f"fragment {i} is seen but its position {position.tolist()} m or angle {angle} rad is not finite (3,)")
    return position, image_angle_to_yaw(angle)


class DebridementEnv(DvrkEnv[DebridementConfig]):
    """Pick the fragments and drop them in the receptacle (the paper's debridement trials).

    Observation (a Dict): ``reported_pose`` (bx, by, bz m; yaw, pitch, roll rad),
    ``jaw_angle`` (rad), and up to eight fragments seen by both cameras, nearest the
    receptacle's side of the image first: ``fragment_positions`` (8, 3) triangulated
    centres in the left camera frame (m), ``fragment_angles`` (8,) the major axis' angle
    in the left image (rad, from +u towards +v), ``fragment_seen`` (8,) 1 where a row
    holds a fragment (other rows are 0).

    Reward: primitive mode 1 for a delivered fragment; delta mode the number of
    fragments let go of in the receptacle for the first time during the step (each once
    per episode; ``info["is_success"]``: every fragment lies there, let go of).

    Reset options:
        ``"relax"``: True relaxes the cables as the arm goes to its start above the
            receptacle, as in a fresh env. False: the arm goes there through its cables,
            which keep their history (hysteresis) from the trials before, as on the real
            robot. Default: True for a seeded reset (a seed alone fixes the trial), False
            otherwise; ``reset(seed=s, options={"relax": False})`` keeps the history with
            a new random stream (the same seed and history give the same trial).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array", "rgb_array_list"], "render_fps": 4}
    config_class = DebridementConfig
    option_names = ("relax",)

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        bias: str | BiasConfig = "paper",
        bias_seed: int = 0,
        fragment: str = "pumpkin_seed",
        action_mode: str = "primitive",
        max_picks: int = paper.FRAGMENTS_PER_TRIAL,
        max_steps: int = 600,
        remove_failed: bool = True,
        timing: PickTiming | dict[str, Any] = DEFAULT_PICK_TIMING,
        gripper: GripperConfig | dict[str, Any] = SERRATED_GRIPPER,
        control_period_s: float = 0.1,
        max_delta_m: float = 0.005,
        max_delta_jaw_rad: float = 0.25,
        delta_yaw_rad: float = 0.0,
        contact: str = DEFAULT_CONTACT,
        camera_resolution: tuple[int, int] = (1920, 1080),
        pixel_noise_px: float = 0.0,
        render_resolution: tuple[int, int] | None = None,
        renderer: str = "auto",
    ) -> None:
        """Debridement-v0, set up by the fields of :class:`DebridementConfig` (listed below)."""
        config = DebridementConfig(**config_arguments(locals()))
        check_fragment_camera("camera_resolution", config.camera_resolution)  # before the world is built
        super().__init__(config, render_mode=render_mode)
        self.primitive = self.config.action_mode == "primitive"
        if self.primitive:
            self.action_names = PICK_ACTION_NAMES
            self.action_space = spaces.Box(PICK_LOW.astype(np.float32), PICK_HIGH.astype(np.float32), dtype=np.float32)
        else:
            self.action_names = DELTA_ACTION_NAMES
            high = np.array([self.config.max_delta_m] * 3 + [self.config.max_delta_jaw_rad], dtype=np.float32)
            self.action_space = spaces.Box(-high, high, dtype=np.float32)
            self.metadata = {**self.metadata, "render_fps": 1.0 / self.config.control_period_s}  # a frame per control step
        box_low = np.tile(CAMERA_BOX_LOW_M, (MAX_FRAGMENTS, 1)).astype(np.float32)
        box_high = np.tile(CAMERA_BOX_HIGH_M, (MAX_FRAGMENTS, 1)).astype(np.float32)
        half_pi = np.float32(math.pi / 2)
        self.observation_space = spaces.Dict(
            {
                **reported_observation_space(),
                "fragment_positions": spaces.Box(box_low, box_high, dtype=np.float32),
                "fragment_angles": spaces.Box(-half_pi, half_pi, shape=(MAX_FRAGMENTS,), dtype=np.float32),
                "fragment_seen": spaces.MultiBinary(MAX_FRAGMENTS),
            }
        )
        self.observer = FragmentObserver(self.world.camera, pixel_noise_px=self.config.pixel_noise_px)
        self.table = DebridementTable(self.world, gripper_config=self.config.gripper, contact=CONTACTS[self.config.contact])
        self.picker = PickPrimitive(self.world, self.table, self.config.timing)
        self._frames: list[np.ndarray] = []  # render_mode "rgb_array_list": frames since the last render()
        if self.render_mode == "rgb_array_list":
            self.picker.on_phase = self._capture_frame
        self._episode = _Episode()

    # ------------------------------------------------------------------ episode
    def _restore_initial_state(self) -> None:
        """Nothing to restore: every reset rebuilds the world (see :meth:`_reset_episode`)."""

    def _reset_episode(self, options: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        world, table = self.world, self.table
        relax = relax_option(options, self._seeded_reset)
        # Rebuilding the physics server (for a deterministic reset: body ids and contact
        # caches carry history) relaxes the cables. Carrying the cable model's state over
        # is enough to keep the arm's history: it is the cables' whole memory (the true
        # joints follow from it and the next command), and the commanded joints before the
        # reset need not be carried, since the arm is commanded to its start, replacing
        # them, and a play operator ends a straight move where it ends a jump.
        cable_state = world.cable.get_state()
        world.rebuild()
        if not relax:
            world.cable.set_state(cable_state)
        world.reset_robot(ik.inverse_kinematics(tool_pose(self.picker.drop_command(0, 0.0), 0.0)), relax=relax)
        table.add_fragments(self.config.fragment, self.np_random)
        self._episode = _Episode(sizes=np.array([f.size_m for f in table.fragments]))
        self._jaw_target = world.jaw_angle
        observation = self._observe()
        info = {"sim_time_s": 0.0, "true_fragment_positions": table.true_fragment_positions(), "fragments_on_paper": len(self._on_paper())}
        self._frames = []
        self._capture_frame()
        return observation, info

    def _step_episode(self, action: np.ndarray, clamped: np.ndarray):
        episode = self._episode
        try:
            if self.primitive:
                reward, info = self._pick(action)
            else:
                reward, info = self._delta(action)
            error = self._physics_failure()
            observation = self._observe() if error is None else self._last_observation
        except (pybullet.error, ValueError, FloatingPointError, np.linalg.LinAlgError) as failure:
            logger.warning("the simulation failed during a step: %s", failure, exc_info=logger.isEnabledFor(logging.DEBUG))
            info = copy.deepcopy(ABORTED_PICK_INFO) if self.primitive else {}  # the same keys as a judged pick's
            reward, error, observation = 0.0, f"{type(failure).__name__}: {failure}", self._last_observation
        episode.steps += 1
        info.update(self._episode_info(failed=error is not None))
        info["clamped"] = self._clamped_names(clamped) + info.pop("clamped_joints", [])
        info["sim_error"] = error
        on_paper = len(self._on_paper()) if error is None else 0
        info["fragments_on_paper"] = on_paper
        # Success of the trial, as SB3 and RL Zoo read it: every fragment in the receptacle.
        info["is_success"] = error is None and len(self._delivered()) == len(self.table.fragments)
        if self.primitive:
            terminated = error is not None or on_paper == 0 or len(episode.outcomes) >= self.config.max_picks
            truncated = False
        else:
            terminated = error is not None or (on_paper == 0 and not self.table.held())
            truncated = not terminated and episode.steps >= self.config.max_steps
            self._capture_frame()
        return observation, float(reward), terminated, truncated, info

    # ------------------------------------------------------------------ rendering
    def render(self) -> np.ndarray | list[Any] | None:
        """The left endoscope image ("rgb_array"), or the frames since the last call
        ("rgb_array_list": the end of each phase of every pick, or one per delta step)."""
        if self.render_mode == "rgb_array_list":
            self._refuse_if_closed("render")
            frames, self._frames = self._frames, []
            return frames
        return super().render()

    def _capture_frame(self) -> None:
        if self.render_mode == "rgb_array_list":
            self._frames.append(self._render_frame())

    # ------------------------------------------------------------------ a pick
    def _pick(self, action: np.ndarray) -> tuple[float, dict[str, Any]]:
        target, yaw = action[:3].astype(float), float(action[3])
        candidates, episode = self._on_paper(), self._episode
        run = self.picker.run(target, yaw, rng=self.np_random, pick=len(episode.outcomes), sizes=episode.sizes, candidates=candidates)
        return self._judge(run)

    def _judge(self, run: PickRun) -> tuple[float, dict[str, Any]]:
        table, episode, record, phase_s = self.table, self._episode, run.record, run.phase_s
        stuck = list(table.held())
        for i in stuck:  # still on the jaws after the drop: the operator takes it off
            table.set_aside_fragment(i)
            episode.set_aside.add(i)
        if record is None:  # nothing was on the paper
            outcome, ratio, index = judge.MISSED, math.inf, -1
        else:
            index, ratio = record.fragment, record.ratio
            episode.picked.add(index)
            delivered = index not in stuck and judge.in_receptacle(table.fragments[index].position())
            outcome = judge.judge(delivered, index in run.pierced, ratio, record.above_top_m)
            if outcome != judge.SUCCESS and self.config.remove_failed and index not in episode.set_aside:
                table.set_aside_fragment(index)
                episode.set_aside.add(index)
        episode.outcomes.append(outcome)
        episode.phase_s.append(np.array(phase_s, dtype=float))
        info = {
            "outcome": outcome,
            "pick_fragment": index,
            "true_grip_offset_ratio": ratio,
            "true_grip_offset_m": None if record is None else record.offset_m,
            "true_tip_at_grip": None if record is None else record.tip,
            "true_tip_above_fragment_m": None if record is None else record.above_top_m,
            "phase_times_s": dict(zip(PHASES, (float(t) for t in phase_s))),
            "pick_time_s": float(np.sum(phase_s)),
            "clamped_joints": [f"joint:{kin.JOINT_NAMES[j]}" for j in np.flatnonzero(run.joints_clamped)],
        }
        return float(outcome == judge.SUCCESS), info

    # ------------------------------------------------------------------ delta control
    def _delta(self, action: np.ndarray) -> tuple[float, dict[str, Any]]:
        table, config = self.table, self.config
        wanted = self.world.reported_pose()[:3, 3] + action[:3]
        target = np.clip(wanted, DELTA_BOX_LOW_M, DELTA_BOX_HIGH_M)
        self._jaw_target = float(np.clip(self._jaw_target + action[3], CLOSED_JAW_RAD, kin.JAW_FULLY_OPEN_RAD))
        table.command_jaws(self._jaw_target)
        pose = tool_pose(target, config.delta_yaw_rad)
        clearance, period = GRASP_TIP_CLEARANCE_M, config.control_period_s
        move = table.move_stepped(pose, noise_rng=self.np_random, min_tip_clearance_m=clearance, duration_s=period)
        table.dwell(period - move.duration_s)
        delivered = self._delivered()
        new = delivered - self._episode.rewarded  # each fragment once: one lifted out and dropped back in scores no more
        self._episode.rewarded |= new
        clamped = [f"position:{axis}" for axis, c in zip("xyz", target != wanted) if c]
        clamped += [f"joint:{kin.JOINT_NAMES[j]}" for j in np.flatnonzero(move.joints_clamped)]
        return float(len(new)), {"clamped_joints": clamped, "delivered": len(delivered)}

    # ------------------------------------------------------------------ what is true
    def _on_paper(self) -> list[int]:
        """Indices of the fragments lying on the paper and not held (truth)."""
        held = self.table.held()
        return [
            i
            for i, f in enumerate(self.table.fragments)
            if i not in self._episode.set_aside and i not in held and f.on_paper(tolerance_m=0.002)
        ]

    def _delivered(self) -> set[int]:
        """Indices of the fragments lying in the receptacle, let go of (truth)."""
        held = self.table.held()
        fragments = self.table.fragments
        return {
            i for i, f in enumerate(fragments) if i not in self._episode.set_aside and i not in held and judge.in_receptacle(f.position())
        }

    def _physics_failure(self) -> str | None:
        world = self.world
        if not (np.isfinite(world.q_true).all() and np.isfinite(world.jaw_angle)):
            return "the robot's joints are not finite"
        live = [i for i in range(len(self.table.fragments)) if i not in self._episode.set_aside]
        return judge.physics_failure(self.table.true_fragment_positions()[live])

    def _episode_info(self, failed: bool) -> dict[str, Any]:
        """The trial's running record; ``failed``: the step ended in a physics failure, whose
        aborted pick is in no outcome, so no fragment counts as taken by another's pick."""
        episode, world = self._episode, self.world
        info: dict[str, Any] = {
            "sim_time_s": world.clock.time_s,
            "true_fragment_positions": self.table.true_fragment_positions(),
            "true_tip_position": world.true_touch_point(),
        }
        if self.primitive:
            picks = len(episode.outcomes)
            counts = judge.outcome_counts(episode.outcomes)
            phases = np.mean(episode.phase_s, axis=0) if picks else np.zeros(len(PHASES))
            unpicked = judge.unpicked_counts(len(self.table.fragments), episode.picked, set(self._on_paper()), self._delivered())
            if failed:
                unpicked = dict.fromkeys(unpicked, 0)
            info.update(
                outcomes=judge.outcome_row(episode.outcomes),
                picks=picks,
                **{f"unpicked_{where}": count for where, count in unpicked.items()},
                successes=counts["success"],
                n_A=counts["A"],
                n_B=counts["B"],
                n_C=counts["C"],
                time_per_fragment=float(np.sum(episode.phase_s) / picks) if picks else 0.0,
                **{f"time_{name}_s": float(t) for name, t in zip(PHASES, phases)},
            )
        return info

    # ------------------------------------------------------------------ what is seen
    def _observe(self) -> dict[str, np.ndarray]:
        detections = self.observer.observe(self.world.physics.client, self.np_random)
        observation = {**encode_reported(self.world.reported_pose(), self.world.jaw_angle), **_encode_fragments(detections)}
        observation = {key: np.nan_to_num(value, nan=0.0, posinf=0.0, neginf=0.0) for key, value in observation.items()}
        observation["jaw_angle"] = np.clip(observation["jaw_angle"], kin.JAW_LOWER_RAD, kin.JAW_UPPER_RAD).astype(np.float32)
        self._last_observation = observation
        return observation


@dataclass
class _Episode:
    """The running record of an episode."""

    sizes: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    outcomes: list[str] = field(default_factory=list)
    phase_s: list[np.ndarray] = field(default_factory=list)
    set_aside: set[int] = field(default_factory=set)
    picked: set[int] = field(default_factory=set)  # primitive mode: fragments a pick went for
    rewarded: set[int] = field(default_factory=set)  # delta mode: fragments whose delivery was rewarded
    steps: int = 0


def _encode_fragments(detections: list[FragmentDetection]) -> dict[str, np.ndarray]:
    positions = np.zeros((MAX_FRAGMENTS, 3), dtype=np.float32)
    angles = np.zeros(MAX_FRAGMENTS, dtype=np.float32)
    seen = np.zeros(MAX_FRAGMENTS, dtype=np.int8)
    for row, detection in enumerate(detections[:MAX_FRAGMENTS]):
        positions[row] = np.clip(detection.camera_position, CAMERA_BOX_LOW_M, CAMERA_BOX_HIGH_M)
        angles[row] = np.clip(detection.image_angle_rad, -math.pi / 2, math.pi / 2)
        seen[row] = 1
    return {"fragment_positions": positions, "fragment_angles": angles, "fragment_seen": seen}
