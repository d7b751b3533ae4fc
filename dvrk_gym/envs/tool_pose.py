"""The tool's pose for a touch or a pick: a position and a yaw, with the paper's pitch and roll."""

from __future__ import annotations

import numpy as np

from dvrk_gym.sim.robot import kinematics as kin

_EYE4 = np.eye(4)
_TOOL_ROTATIONS: dict[str, np.ndarray] = {}
_MAX_CACHED_ROTATIONS = 256


def tool_rotation(yaw_rad: float) -> np.ndarray:
    """The tool's rotation (3, 3) at ``yaw_rad`` with the paper's pitch and roll, made once per
    yaw (a touch or a pick asks for the same yaw a dozen times). Keyed by the float's exact
    value, so -0.0 and 0.0 keep their own (sines of opposite sign)."""
    key = float(yaw_rad).hex()
    rotation = _TOOL_ROTATIONS.get(key)
    if rotation is None:
        if len(_TOOL_ROTATIONS) >= _MAX_CACHED_ROTATIONS:
            _TOOL_ROTATIONS.clear()
        pitch, roll = kin.paper_pitch_roll(yaw_rad)
        rotation = kin.pose_from_euler(np.zeros(3), yaw_rad, float(pitch), float(roll))[:3, :3].copy()
        rotation.flags.writeable = False
        _TOOL_ROTATIONS[key] = rotation
    return rotation


def tool_pose(position: np.ndarray, yaw_rad: float) -> np.ndarray:
    """The tool pose at ``position`` (reported frame, m) with ``yaw`` and the paper's pitch and roll."""
    pose = _EYE4.copy()
    pose[:3, :3] = tool_rotation(yaw_rad)
    pose[:3, 3] = kin.finite_vector(position, 3, "position")
    return pose
