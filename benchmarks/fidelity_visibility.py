"""Which orientations keep their Phase I rows, on the real robot and the simulated one, and why.

``dvrk-gym fidelity`` finds the kept rows' median pitch at yaw 90 at -6 degrees where the real
rows' is -1, and the DNN's yaw-90 cell of the calibration table 3.4 mm against the paper's 2.0.
This script measures the chain between the two:

1. **Kept rows per nearest paper yaw**, real and simulated (the ``paper`` instrument, the
   paper's 57 trajectories): how many, their pitch (10th / 50th / 90th percentile) and
   their median roll, degrees.
2. **What hides the tape.** Every raw row's true joints are recorded during the collection
   and rendered again with a detector that never misses: the share of rows whose tape both
   cameras see inside the authors' search boxes (:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`),
   per nearest yaw, and for a hidden one whether it lay outside a box, or else what the left
   camera's rays to the tape's faces meet first (the clevis, the shaft, the jaws), or that
   no face turns towards the camera or what shows is too thin for the median filter. Beside it, the real robot's
   share, estimated: its kept rows at that yaw, over the raw rows the protocol commands
   there (the simulated collection's, scaled to the authors' 5,256), over the share that
   survives the detector's random misses in both images. Then the angle between the jaws
   and the line of sight to the tape over the kept rows, real (their reported poses through
   the identified instrument) and simulated: the angles at which each robot saw its tape.
3. **What would move it.** The same recorded joints rendered under other instruments: the
   camera orbited about the workspace centre (its position and view turned together by 10
   or 20 degrees about the base x or y axis), and constant offsets on the roll or wrist-pitch
   joint. The kept share per yaw and median pitch per yaw of each, beside the real ones.
4. With ``--calibration DIR`` (a ``dvrk-gym calibrate`` folder): the DNN's mean touch error
   at yaw 90, 45 and -90 when the touches hold the paper's pitch minus 0, 5, 10 or 19
   degrees (the touch rule's pitch is offset for this measurement only): how much of the
   yaw-90 cell is the DNN extrapolating in pitch.
5. With ``--camera-fit``: whether the real rows' pixels allow the camera orbits of part 3.
   The identification (:func:`dvrk_gym.fidelity.identify.fit_parameters`) on its training
   rows, then again with the camera's position held at each orbit of 10 or 20 degrees and
   every other parameter (the camera's rotation too) fitted afresh: the pixel residuals
   (u, v, disparity RMS) on the training and held-out rows, and where the fit puts the tape.
   The same with the roll or wrist-pitch homing offset held at 15 to 30 degrees: the
   pixels pin the roll, but a wrist-pitch offset trades with the tape's height on the jaws.

    python benchmarks/fidelity_visibility.py                        # about 3 min
    python benchmarks/fidelity_visibility.py --calibration DIR      # 10 s more
    python benchmarks/fidelity_visibility.py --camera-fit           # about 3 min more
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
from scipy.spatial.transform import Rotation

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.models.features import nearest_yaw_index
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, collect_phase1
from dvrk_gym.fidelity.instrument_model import real_commands
from dvrk_gym.fidelity.statistics import PAPER_YAWS_DEG
from dvrk_gym.sim.endoscope.camera import WORKSPACE_CENTER_M, default_camera_pose
from dvrk_gym.sim.endoscope.noise import whole_pixels
from dvrk_gym.sim.identified import MARKER_DETECTION_NOISE
from dvrk_gym.sim.robot import body
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.world import DvrkWorld
from dvrk_gym.sim.world_config import WorldConfig

_LINK_NAMES = {3: "shaft", 4: "clevis", 5: "pivot", 6: "jaw A", 7: "jaw B"}
_RAY_STANDOFF_M = 2.0e-5
"""Rays stop this far in front of the tape's faces, so they cannot meet the jaw beneath."""


class JointRecorder(gym.Wrapper):
    """Keeps the true joints (rad, insertion m) and jaw angle (rad) after every step of a
    CalibrationExploration-v0 env: the rows a collection makes, one each."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.joints: list[np.ndarray] = []

    def step(self, action):  # type: ignore[no-untyped-def]
        result = self.env.step(action)
        world = self.env.unwrapped.world
        self.joints.append(np.r_[world.q_true, world.jaw_angle])
        return result


def per_yaw_rows(orientation: np.ndarray) -> list[tuple[int, float, float, float, float]]:
    """Per paper yaw: rows, pitch 10th / 50th / 90th percentile and median roll (degrees, roll in (-360, 0])."""
    near = nearest_yaw_index(orientation[:, 0])
    rows = []
    for k in range(len(PAPER_YAWS_DEG)):
        pitch = np.rad2deg(orientation[near == k, 1])
        roll = (np.rad2deg(orientation[near == k, 2]) + 360.0) % 360.0 - 360.0
        if len(pitch) == 0:
            rows.append((0, np.nan, np.nan, np.nan, np.nan))
            continue
        p10, p50, p90 = np.percentile(pitch, [10, 50, 90])
        rows.append((len(pitch), float(p10), float(p50), float(p90), float(np.median(roll))))
    return rows


def shares_and_medians(orientation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Share of rows per paper yaw, and their median pitch (degrees)."""
    near = nearest_yaw_index(orientation[:, 0])
    shares = np.bincount(near, minlength=len(PAPER_YAWS_DEG)) / max(len(near), 1)
    medians = np.array([np.rad2deg(np.median(orientation[near == k, 1])) if np.any(near == k) else np.nan for k in range(5)])
    return shares, medians


def orbited_camera(axis: tuple[float, float, float], angle_deg: float, pose: np.ndarray | None = None) -> np.ndarray:
    """A camera pose (4x4; default: the identified camera's) turned by ``angle_deg`` about
    ``axis`` (base frame) through the workspace centre: position and view turn together."""
    turn = Rotation.from_rotvec(np.deg2rad(angle_deg) * np.asarray(axis, dtype=float)).as_matrix()
    pose = (default_camera_pose() if pose is None else pose).copy()
    centre = np.asarray(WORKSPACE_CENTER_M)
    pose[:3, :3] = turn @ pose[:3, :3]
    pose[:3, 3] = centre + turn @ (pose[:3, 3] - centre)
    return pose


def hidden_by(world: DvrkWorld) -> str:
    """What the left camera's rays to the tape's faces meet first, by majority, or why no ray goes out."""
    origin = world.camera.pose[:3, 3]
    points, normals = body.marker_face_samples(world.q_true, origin, world.cable.true_dh)
    if len(points) == 0:
        return "faces away"
    ends = points + _RAY_STANDOFF_M * normals
    hits = world.physics.client.rayTestBatch([list(origin)] * len(ends), ends.tolist())
    names = [
        _LINK_NAMES.get(hit[1], "scene") if hit[0] == world.robot.body_id else ("nothing" if hit[0] == -1 else "scene") for hit in hits
    ]
    blockers = [name for name in names if name != "nothing"]
    if len(blockers) < len(names) / 2:
        return "too thin"
    return max(set(blockers), key=blockers.count)


def in_search_boxes(world: DvrkWorld, left_uv: np.ndarray, right_uv: np.ndarray) -> bool:
    """Whether exact detections lie where the authors' tape detector searched
    (:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`), in whole pixels, the right one shifted
    as the detector reports it: a tape seen outside is a row the detector loses."""
    noise, width = world.config.marker_noise, world.camera.intrinsics.width
    right = right_uv + noise.shift("right", width)
    return noise.searches("left", whole_pixels(left_uv, width), width) and noise.searches("right", whole_pixels(right, width), width)


def jaws_from_line_of_sight_deg(world: DvrkWorld) -> float:
    """Angle between the closed jaws' direction (pivot to tips) and the left camera's ray to the tape, degrees."""
    frame = body.marker_frame(world.q_true, world.cable.true_dh)
    ray = body.marker_position(world.q_true, world.cable.true_dh) - world.camera.pose[:3, 3]
    cosine = float(frame[:3, 1] @ ray / np.linalg.norm(ray))
    return float(np.rad2deg(np.arccos(np.clip(cosine, -1.0, 1.0))))


def real_rows_true_joints(world: DvrkWorld, real_X: np.ndarray, real_y: np.ndarray) -> np.ndarray:
    """The true joints (N, 6) of the real rows: their reported poses through the nominal inverse
    kinematics and ``world``'s cables (the identified instrument's in a fresh world), in the
    rows' order, as the identification runs them."""
    return np.array([world.cable.true_joints(command) for command in real_commands(real_X, real_y)])


def real_rows_jaw_angles_deg(real_X: np.ndarray, real_y: np.ndarray) -> np.ndarray:
    """The jaws' angle from the line of sight (degrees) for each real row (:func:`real_rows_true_joints`),
    seen by the identified camera."""
    world = DvrkWorld(WorldConfig())
    try:
        angles = []
        for q in real_rows_true_joints(world, real_X, real_y):
            world.q_true = q
            angles.append(jaws_from_line_of_sight_deg(world))
    finally:
        world.close()
    return np.array(angles)


def render_rows(joints: np.ndarray, camera_pose: np.ndarray | None = None, offsets_rad: np.ndarray | None = None, why: bool = False):  # type: ignore[no-untyped-def]
    """Which rows' tape both cameras see (noise-free pixel path) inside the authors' search boxes, with the joints ``joints``
    ((N, 7): six joints and the jaw) plus ``offsets_rad`` (6,), seen by ``camera_pose``;
    with ``why``, also what hid each hidden row and the jaws' angle from the line of sight."""
    world = DvrkWorld(WorldConfig(camera_pose=camera_pose))
    seen = np.zeros(len(joints), dtype=bool)
    reasons: list[str] = []
    angles = np.zeros(len(joints))
    try:
        for i, row in enumerate(joints):
            q = row[:6] + (0.0 if offsets_rad is None else offsets_rad)
            world.q_true = q.copy()
            world.jaw_angle = float(row[6])
            world.robot.set_joints(q, float(row[6]))
            detection = world.observe_marker(None)
            visible = bool(np.all(np.isfinite(detection.left_uv)) and np.all(np.isfinite(detection.right_uv)))
            seen[i] = visible and in_search_boxes(world, detection.left_uv, detection.right_uv)
            if why:
                reasons.append("seen" if seen[i] else "outside box" if visible else hidden_by(world))
                angles[i] = jaws_from_line_of_sight_deg(world)
    finally:
        world.close()
    return (seen, reasons, angles) if why else seen


@contextlib.contextmanager
def touch_pitch_offset(offset_rad: float) -> Iterator[None]:
    """The paper's touch rule with its pitch moved by ``offset_rad``, for a measurement only."""
    from dvrk_gym.envs import tool_pose

    original = kin.paper_pitch_roll

    def offset_rule(yaw_rad):  # type: ignore[no-untyped-def]
        pitch, roll = original(yaw_rad)
        return pitch + offset_rad, roll

    kin.paper_pitch_roll = offset_rule  # type: ignore[assignment]
    tool_pose._TOOL_ROTATIONS.clear()
    try:
        yield
    finally:
        kin.paper_pitch_roll = original  # type: ignore[assignment]
        tool_pose._TOOL_ROTATIONS.clear()


def dnn_against_touch_pitch(folder: str) -> None:
    """Part 4: the DNN's mean touch error at three yaws against the touches' pitch."""
    from dvrk_gym.calibration.benchmark import BENCHMARK_SEED, touch_grid
    from dvrk_gym.calibration.loading import load_calibrator
    from dvrk_gym.calibration.policy import CalibratedPolicy

    model, settings = load_calibrator(folder, "dnn")
    print(f"\nThe DNN of {folder} (instrument {settings.get('bias_seed', 0)}): mean touch error, mm (px), 35 circles")
    print("yaw   touch pitch: paper's  -5 deg  -10 deg  -19 deg")
    for yaw_deg, setting in ((90.0, 4), (45.0, 3), (-90.0, 0)):
        cells = []
        for offset in (0.0, -5.0, -10.0, -19.0):
            with touch_pitch_offset(np.deg2rad(offset)):
                env = gym.make("dvrk_gym/GridTouch-v0", bias=settings.get("bias", "paper"), bias_seed=settings.get("bias_seed", 0))
                try:
                    errors = touch_grid(env, CalibratedPolicy(model), np.deg2rad(yaw_deg), seed=BENCHMARK_SEED + setting)
                finally:
                    env.close()
            cells.append(f"{np.nanmean(errors.mm):.2f} ({np.nanmean(errors.pixel):.0f})")
        pitch = np.rad2deg(kin.paper_pitch_roll(np.deg2rad(yaw_deg))[0])
        print(f"{yaw_deg:+4.0f}  ({pitch:4.1f} deg)   " + "  ".join(f"{c:>12s}" for c in cells))


def camera_fit_along_orbits() -> None:
    """Part 5: the identification's pixel residuals with the camera held at orbited positions,
    and with the roll or wrist-pitch homing offset held far from its fitted value."""
    from dvrk_gym.fidelity import identify
    from dvrk_gym.fidelity.instrument_model import PARAMETER_NAMES, PARAMETERS, camera_pose, real_commands, real_pixels

    X, y = load_paper_phase1()
    commands, pixels = real_commands(X, y), real_pixels(X)
    train, held = identify.split(len(X))
    fit = identify.fit_parameters(commands[train], pixels[train])
    tape = [PARAMETER_NAMES.index(name) for name in ("marker_x", "marker_y", "marker_z")]
    position = tuple(PARAMETER_NAMES.index(name) for name in ("camera_x", "camera_y", "camera_z"))

    def report(label: str, theta: np.ndarray) -> None:
        train_rms = identify.residual_rms(theta, commands[train], pixels[train])
        held_rms = identify.residual_rms(theta, commands[held], pixels[held])
        print(f"{label:42s} {_fmt(train_rms, '5.2f')} | {_fmt(held_rms, '5.2f')} | {_fmt(theta[tape] * 1e3, '5.2f')}", flush=True)

    def refit_holding(theta: np.ndarray, held_indices: tuple[int, ...]) -> np.ndarray:
        free = tuple(i for i in range(len(PARAMETERS)) if i not in held_indices)
        return identify.refit(identify.InstrumentFit(theta, fit.scales, free), commands[train], pixels[train]).theta

    print("\n5. The identification's pixel residuals, px RMS (u, v, disparity), training | held-out rows | its tape point (x, y, z)")
    print("   in the wrist-yaw frame, mm (the jaws' faces are at x = +-1.1 mm and z = +-1.3 mm; they run along y)")
    report("as identified (camera free)", fit.theta)
    for axis_name, axis in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0))):
        for angle in (-20.0, -10.0, 10.0, 20.0):
            moved = orbited_camera(axis, angle, pose=camera_pose(fit.theta)[0])
            theta = fit.theta.copy()
            theta[0:3] = Rotation.from_matrix(moved[:3, :3]).as_rotvec()
            theta[3:6] = moved[:3, 3]
            report(f"camera held orbited {angle:+.0f} deg about base {axis_name}", refit_holding(theta, position))
    for name, label, degrees in (
        ("homing_wrist_pitch", "wrist-pitch", -15.0),
        ("homing_wrist_pitch", "wrist-pitch", -30.0),
        ("homing_roll", "roll", 15.0),
        ("homing_roll", "roll", -20.0),
    ):
        theta = fit.theta.copy()
        theta[PARAMETER_NAMES.index(name)] = np.deg2rad(degrees)
        report(f"{label} homing offset held at {degrees:+.0f} deg", refit_holding(theta, (PARAMETER_NAMES.index(name),)))


def _fmt(values: np.ndarray, spec: str) -> str:
    return " ".join(format(v, spec) for v in values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories (default: the paper's 57)"
    )
    parser.add_argument("--every", type=int, default=2, help="render every this many raw rows again in part 3 (default: 2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--calibration", default=None, help="a dvrk-gym calibrate folder: also run part 4")
    parser.add_argument("--camera-fit", action="store_true", help="also run part 5 (the identification refitted per orbit)")
    args = parser.parse_args()
    if args.trajectories < 1 or args.every < 1:
        parser.error("--trajectories and --every must be at least 1")

    env = JointRecorder(gym.make("dvrk_gym/CalibrationExploration-v0", max_steps=paper.PHASE1_POSES_PER_TRAJECTORY))
    try:
        data = collect_phase1(env, PaperExplorationPolicy(seed=args.seed), args.trajectories, seed=args.seed, progress=False)
    finally:
        env.close()
    joints = np.array(env.joints)
    real_X, real_y = load_paper_phase1()
    kept = data.orientation[data.kept]

    print(f"1. Kept rows per nearest paper yaw (real: 1939 rows; simulated: {data.n_kept} of {data.n_raw}, instrument 0)")
    print("yaw    real: rows  pitch p10/p50/p90  roll p50 | sim: rows  pitch p10/p50/p90  roll p50")
    for yaw, r, s in zip(PAPER_YAWS_DEG, per_yaw_rows(real_X[:, 3:6]), per_yaw_rows(kept)):
        real_part = f"{r[0]:10d}  {r[1]:6.1f} {r[2]:5.1f} {r[3]:5.1f}  {r[4]:7.1f}"
        print(f"{yaw:+4.0f}  {real_part} | {s[0]:9d}  {s[1]:6.1f} {s[2]:5.1f} {s[3]:5.1f}  {s[4]:7.1f}")

    seen, reasons, angles = render_rows(joints, why=True)
    near = nearest_yaw_index(data.orientation[:, 0])
    causes = ("outside box", "clevis", "shaft", "jaw A", "jaw B", "pivot", "faces away", "too thin", "scene")
    # The real robot's share seen, estimated: its kept rows per yaw over the raw rows the same
    # protocol commands there (the simulated raw rows, scaled to the authors' 5256), over the
    # share a detector that misses each image at random keeps ((1 - miss)^2).
    survive = (1.0 - MARKER_DETECTION_NOISE.miss_probability) ** 2
    real_counts = np.bincount(nearest_yaw_index(real_X[:, 3]), minlength=len(PAPER_YAWS_DEG))
    print("\n2. Raw rows whose tape both cameras see without misses, and what hides the others (left camera), per nearest yaw;")
    print(
        "   real: estimated from its kept rows, the raw rows the protocol commands there and the detector's misses"
        f" ({MARKER_DETECTION_NOISE.miss_probability:.3f} per image)"
    )
    print("   angle: the jaws' direction from the left camera's line of sight to the tape, median over the raw rows, deg")
    print("yaw   raw  real  seen  angle  " + "  ".join(f"{c:>10s}" for c in causes))
    for k, yaw in enumerate(PAPER_YAWS_DEG):
        rows = near == k
        hidden = [reasons[i] for i in np.flatnonzero(rows & ~seen)]
        shares = [hidden.count(c) / max(rows.sum(), 1) for c in causes]
        real_seen = real_counts[k] / max(rows.sum() * paper.PHASE1_RAW_SAMPLES / data.n_raw, 1e-9) / survive
        angle = np.median(angles[rows]) if rows.any() else np.nan
        head = f"{yaw:+4.0f} {rows.sum():5d}  {real_seen:.2f}  {seen[rows].mean():.2f}  {angle:5.1f}  "
        print(head + "  ".join(f"{v:10.2f}" for v in shares))

    real_angles = real_rows_jaw_angles_deg(real_X, real_y)
    real_near = nearest_yaw_index(real_X[:, 3])
    print("\n   The jaws' angle from the line of sight, deg, 5th / 25th / 50th percentile over the kept rows: real (their poses")
    print("   through the identified instrument) | simulated; and the share of kept rows under 15 degrees")
    for k, yaw in enumerate(PAPER_YAWS_DEG):
        real_k, sim_k = real_angles[real_near == k], angles[(near == k) & data.kept]
        parts = [f"{_fmt(np.percentile(a, [5, 25, 50]), '5.1f')}  {np.mean(a < 15.0):.2f}" if len(a) else "  none" for a in (real_k, sim_k)]
        print(f"{yaw:+4.0f}  {parts[0]} | {parts[1]}")

    real_shares, real_medians = shares_and_medians(real_X[:, 3:6])
    subset = np.arange(0, len(joints), args.every)
    variants: list[tuple[str, dict]] = [("as identified", {})]
    for axis_name, axis in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0))):
        for angle in (-20.0, -10.0, 10.0, 20.0):
            variants.append((f"camera orbited {angle:+.0f} deg about base {axis_name}", {"camera_pose": orbited_camera(axis, angle)}))
    for joint, name in ((3, "roll"), (4, "wrist pitch")):
        for angle in (-15.0, 15.0):
            offsets = np.zeros(6)
            offsets[joint] = np.deg2rad(angle)
            variants.append((f"{name} joint {angle:+.0f} deg", {"offsets_rad": offsets}))
    print(f"\n3. Seen rows (one raw row in {args.every}, no misses) per nearest yaw -90 .. 90: share of the seen rows, median pitch (deg)")
    print(f"{'real (kept rows)':40s} {_fmt(real_shares, '.2f')} | {_fmt(real_medians, '6.1f')}")
    for label, options in variants:
        seen_here = render_rows(joints[subset], **options)
        shares, medians = shares_and_medians(data.orientation[subset][seen_here])
        print(f"{label:40s} {_fmt(shares, '.2f')} | {_fmt(medians, '6.1f')}   seen {seen_here.mean():.2f}", flush=True)

    if args.calibration is not None:
        dnn_against_touch_pitch(args.calibration)
    if args.camera_fit:
        camera_fit_along_orbits()


if __name__ == "__main__":
    main()
