"""The cable model's tip-error field over the paper's grid, and its figure.

One subplot per paper yaw (-90, -45, 0, 45, 90 deg). Each shows, on a 7 x 5 grid like the
paper's 35 circles (pitch and roll from the paper's rule for that yaw, each point
approached from rest, no noise), the x-y part of the tip error as arrows coloured by the
3-D norm: the residual after a rigid fit per yaw (what the paper's rigid-body calibration
leaves), or the raw error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.sim.robot.bias_statistics import WORKSPACE_X_M, WORKSPACE_Y_M, rigid_fit_residuals
from dvrk_gym.sim.robot.cables import CableModel
from dvrk_gym.utils.atomic import atomic_savefig

GRID_SHAPE = (7, 5)
"""Points along base x and y: 35, as many as the paper's circles, spread evenly over the
whole workspace (``WORKSPACE_X_M`` by ``WORKSPACE_Y_M``), which reaches a little past the
printed circles (``dvrk_gym.sim.physics.scene.grid_circle_centers``)."""
GRID_Z_M = -0.159
"""Height of the grid: the middle of the paper's workspace, metres (base frame)."""
FIELDS = ("rigid", "raw")
MM_PER_M = 1e3
ARROW_FILL = 0.8
"""The figure's longest arrow spans at most this share of the grid's spacing: drawn 1:1, a
0.3 mm error on a 12 mm grid was a dot."""


def round_down(value: float) -> float:
    """The largest of 1, 2 or 5 times a power of ten that is at most ``value`` (> 0)."""
    decade = 10.0 ** np.floor(np.log10(value))
    return float(max(step * decade for step in (1.0, 2.0, 5.0) if step * decade <= value * (1.0 + 1e-12)))


def arrow_magnification(longest_mm: float, spacing_mm: float) -> float:
    """How many times their length the figure draws the errors (a round number): the longest
    then spans at most :data:`ARROW_FILL` of the grid's spacing (both lengths in mm)."""
    return round_down(ARROW_FILL * spacing_mm / longest_mm) if longest_mm > 0.0 else 1.0


def grid_errors(model: CableModel, yaw_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Reported touch points and raw tip errors (both (35, 3), metres) on the grid at one yaw."""
    pitch, roll = kin.paper_pitch_roll(yaw_rad)
    xs = np.linspace(*WORKSPACE_X_M, GRID_SHAPE[0])
    ys = np.linspace(*WORKSPACE_Y_M, GRID_SHAPE[1])
    reported, errors = [], []
    for x in xs:
        for y in ys:
            pose = kin.pose_from_euler(np.array([x, y, GRID_Z_M]), yaw_rad, float(pitch), float(roll))
            q_cmd = ik.inverse_kinematics(pose)
            model.reset(q_cmd)
            true = kin.touch_point(model.true_joints(q_cmd), model.true_dh)
            reported.append(kin.touch_point(q_cmd))
            errors.append(true - reported[-1])
    return np.array(reported), np.array(errors)


def grid_field(model: CableModel, yaw_rad: float, field: str = "rigid") -> tuple[np.ndarray, np.ndarray]:
    """Reported touch points and the ``field`` ("rigid" residual or "raw" error), metres."""
    if field not in FIELDS:
        raise ValueError(f"field must be one of {FIELDS}, got {field!r}")
    reported, errors = grid_errors(model, yaw_rad)
    if field == "rigid":
        errors = rigid_fit_residuals(reported, reported + errors)
    return reported, errors


def grid_rigid_means(model: CableModel) -> list[float]:
    """Per-yaw mean residual (m) of a rigid fit on the grid: the cables' share of an RBT row,
    noiseless (no camera, tape or touch; the grid is the workspace's, not the printed circles)."""
    return [float(np.linalg.norm(grid_field(model, yaw)[1], axis=1).mean()) for yaw in kin.PAPER_YAWS_RAD]


def model_name(model: CableModel) -> str:
    """The preset name of the model's configuration, or 'custom'."""
    return next((name for name, config in BIAS_PRESETS.items() if config == model.config), "custom")


def plot_field(model: CableModel, path: Path, field: str = "rigid") -> Path:
    """Write the figure of the raw or rigid-fit-residual field (PNG), one subplot per yaw."""
    from matplotlib.figure import Figure

    fields = [grid_field(model, yaw, field) for yaw in kin.PAPER_YAWS_RAD]
    norms_mm = [np.linalg.norm(errors, axis=1) * MM_PER_M for _, errors in fields]
    vmax = max(norm.max() for norm in norms_mm)
    spacing_mm = MM_PER_M * min(np.ptp(WORKSPACE_X_M) / (GRID_SHAPE[0] - 1), np.ptp(WORKSPACE_Y_M) / (GRID_SHAPE[1] - 1))
    longest_mm = max(np.linalg.norm(errors[:, :2], axis=1).max() for _, errors in fields) * MM_PER_M
    magnification = arrow_magnification(longest_mm, spacing_mm)
    figure = Figure(figsize=(20, 4.6), layout="constrained")
    axes = figure.subplots(1, len(kin.PAPER_YAWS_RAD))
    for ax, yaw, (reported, errors), norm_mm in zip(axes, kin.PAPER_YAWS_RAD, fields, norms_mm):
        tails, arrows = reported[:, :2] * MM_PER_M, errors[:, :2] * MM_PER_M * magnification
        quiver = ax.quiver(
            tails[:, 0],
            tails[:, 1],
            arrows[:, 0],
            arrows[:, 1],
            norm_mm,
            cmap="viridis",
            clim=(0.0, vmax),
            angles="xy",
            scale_units="xy",
            scale=1.0,
            width=0.006,
        )
        ends = np.vstack([tails, tails + arrows])
        pad_mm = 3.0  # room for the arrow heads
        ax.set_xlim(ends[:, 0].min() - pad_mm, ends[:, 0].max() + pad_mm)
        ax.set_ylim(ends[:, 1].min() - pad_mm, ends[:, 1].max() + pad_mm)
        ax.set_title(f"yaw {np.rad2deg(yaw):+.0f} deg: mean {norm_mm.mean():.2f} mm (3-D)")
        ax.set_xlabel("base x (mm)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("base y (mm)")
    if longest_mm > 0.0:  # a key arrow of a round length, as long as the longest or a little shorter
        key_mm = round_down(longest_mm)
        axes[-1].quiverkey(quiver, 0.85, 1.12, key_mm * magnification, f"{key_mm:g} mm", labelpos="W", coordinates="axes")
    label = "after a rigid fit per yaw" if field == "rigid" else "raw"
    figure.colorbar(quiver, ax=axes, label="3-D norm (mm)")
    figure.suptitle(
        f"Cable model '{model_name(model)}', bias seed {model.bias_seed}: tip error {label} "
        f"(arrows: its x-y part, drawn {magnification:g} times its length; colour: its 3-D norm; "
        "grid of 35 points, paper's pitch and roll for each yaw; noiseless)"
    )
    return atomic_savefig(figure, path, dpi=110)
