"""Identify how the paper gives way under the jaws, from the authors' records of their table's runs.

The records (:func:`~dvrk_gym.calibration.datasets.load_paper_table_runs`) keep, for each of
the 630 touches behind the paper's calibration table, where the robot was sent, where it
reported itself after the move, and where a person saw the end effector in the left image;
and, from the same days, the jaws pushed onto the circles (whose reported heights lie on a
plane to 0.15-0.34 mm). A touch sent ``depth`` under that plane met the paper before its
command; what the records show it did then:

- **give**: the arm reported itself ``give * depth`` over where it was sent (the motors
  stopped short, held off by the paper), where the rigid body's touches sent over the paper
  reported themselves where they were sent (a slope of 0.0 on the height over it);
- **slide**: the end effector landed ``slide * depth`` from where a touch over the paper
  lands, along one direction of the table's plane: further right in the image the deeper it
  was sent (a slope of 0.0 for the rigid body's touches over the paper).

Both are straight lines through the touches with a free intercept per run (one method at one
yaw): the give on the reported minus the sent height, the slide on the image offsets,
through the image's Jacobian of the plane (the identified camera,
:func:`~dvrk_gym.sim.endoscope.camera.default_camera_pose`), so the slide comes out in the
robot's frame, metres per metre. They are fitted on the rigid body's runs (its touches went
up to 10 mm under the paper; the networks' hardly 2) and set beside the networks' runs,
which the fit never saw and which do not confirm the slide: their touches went a few tenths
of a millimetre under, and their offsets go with the height they were sent at over the
paper too (:data:`dvrk_gym.sim.identified.PAPER_CONTACT` has the figures).
``python benchmarks/identify_contact.py`` prints every figure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import PaperTableRuns
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.utils.checks import check_float

__all__ = ["ContactFit", "FIXED_SETTINGS", "depth_under_pushes", "fit_contact", "height_over_pushes", "pushes_of_run"]

FIXED_SETTINGS = 5
"""The table's first five settings are the fixed yaws, the ones with Phase II pushes."""
JACOBIAN_STEP_M = 1e-3
"""The step of the image's finite-difference Jacobian of the plane, metres."""
MAX_DEAD_ZONE_M = 0.01
"""The largest dead zone :func:`fit_contact` takes, metres (the rigid body's touches went 10 mm deep)."""


@dataclass(frozen=True)
class ContactFit:
    """One fit of :func:`fit_contact`.

    Attributes:
        slide_per_depth: (2,) how far the jaws slide along the robot's x and y per metre sent
            under the paper, metres per metre.
        slide_se: (2,) its standard errors (least squares), metres per metre.
        give: the share of the depth the arm reports itself over where it was sent.
        give_se: its standard error.
        touches: how many touches the fit used.
        touches_under: how many of them were sent under the paper, beyond the dead zone.
        dead_zone_m: the depth under the plane of the pushes at which both lines begin, m.
        slide_rms_px: the RMS residual of the image offsets about the fit, left-image pixels.
        give_rms_m: the RMS residual of the reported-minus-sent heights about the fit, m.
    """

    slide_per_depth: np.ndarray
    slide_se: np.ndarray
    give: float
    give_se: float
    touches: int
    touches_under: int
    dead_zone_m: float
    slide_rms_px: float
    give_rms_m: float


def pushes_of_run(runs: PaperTableRuns, method: str, setting: int) -> np.ndarray:
    """The real Phase II pushes (n, 3) m at a fixed-yaw ``setting``'s yaw, from the day of
    ``method``'s runs (:data:`~dvrk_gym.paper.TABLE_PUSH_ROUND`)."""
    if not 0 <= setting < FIXED_SETTINGS:
        raise ValueError(f"setting must be a fixed yaw's, 0-{FIXED_SETTINGS - 1}; got {setting}")
    if method not in paper.TABLE_PUSH_ROUND:
        raise ValueError(f"method must be one of {sorted(paper.TABLE_PUSH_ROUND)}, got {method!r}")
    same = np.isclose(np.rad2deg(runs.push_yaw), paper.PHASE2_YAWS_DEG[setting]) & (runs.push_round == paper.TABLE_PUSH_ROUND[method])
    return runs.push_after[same]


def height_over_pushes(points: np.ndarray, pushed: np.ndarray) -> np.ndarray:
    """Heights (n,) m of ``points`` (n, 3) m over the least-squares plane through ``pushed``
    (m, 3) m (negative under it). Raises ValueError for fewer than three pushes."""
    if len(pushed) < 3:
        raise ValueError(f"a plane needs at least three pushed positions, got {len(pushed)}")
    design = np.c_[pushed[:, :2], np.ones(len(pushed))]
    plane, *_ = np.linalg.lstsq(design, pushed[:, 2], rcond=None)
    return points[:, 2] - np.c_[points[:, :2], np.ones(len(points))] @ plane


def depth_under_pushes(points: np.ndarray, pushed: np.ndarray) -> np.ndarray:
    """How far (n,) m ``points`` (n, 3) m lie under the plane through ``pushed`` (m, 3) m
    (:func:`height_over_pushes`; 0 for a point over it)."""
    return np.maximum(-height_over_pushes(points, pushed), 0.0)


def _plane_jacobian(camera: StereoCamera, point: np.ndarray) -> np.ndarray:
    """(2, 2) left-image pixels per metre along the robot's x and y at ``point`` (3,) m."""
    step = JACOBIAN_STEP_M
    uv, _ = camera.project(np.array([point, point + [step, 0.0, 0.0], point + [0.0, step, 0.0]]))
    return np.c_[uv[1] - uv[0], uv[2] - uv[0]] / step


def _least_squares(design: np.ndarray, target: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The first ``columns`` coefficients of the least-squares fit, their standard errors, and
    the RMS residual."""
    coefficients, *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = target - design @ coefficients
    dof = len(target) - design.shape[1]
    if dof <= 0:
        raise ValueError(f"too few touches to fit: {len(target)} equations for {design.shape[1]} unknowns")
    covariance = np.linalg.pinv(design.T @ design) * float(residual @ residual) / dof
    return coefficients[:columns], np.sqrt(np.diag(covariance)[:columns]), float(np.sqrt(residual @ residual / len(target)))


def fit_contact(runs: PaperTableRuns, methods: tuple[str, ...], camera: StereoCamera | None = None, dead_zone_m: float = 0.0) -> ContactFit:
    """Fit the give and the slide (module docstring) to the fixed-yaw runs of ``methods``.

    Args:
        runs: the authors' records of the table's runs.
        methods: which methods' runs ("RBT", "DNN", "DNN+RF"), each at the five fixed yaws.
        camera: the endoscope whose left image the offsets are measured in; default the
            identified one.
        dead_zone_m: fit both lines on the depth beyond this much under the plane of the
            pushes (a hinge: nothing gives or slides before it), in [0, 0.01] m; 0 is the
            straight lines the simulator uses. Comparing the fits' residuals says where the
            records put a hinge.

    Raises ValueError if no touch of ``methods`` was sent beyond the dead zone, for a
    dead zone out of range, or for ``methods`` unknown or repeated (a repeat would count
    its touches twice).
    """
    unknown = set(methods) - set(paper.METHOD_LABELS.values())
    if not methods or unknown or len(set(methods)) != len(methods):
        raise ValueError(f"methods must be some of {sorted(paper.METHOD_LABELS.values())}, each once, got {methods}")
    dead_zone = check_float("dead_zone_m", dead_zone_m, low=0.0, high=MAX_DEAD_ZONE_M, unit="m")
    camera = StereoCamera() if camera is None else camera
    slide_rows, offsets, rise_rows, rises = [], [], [], []
    runs_total = len(methods) * FIXED_SETTINGS
    for run, (method, setting) in enumerate((m, s) for m in methods for s in range(FIXED_SETTINGS)):
        mine = (runs.method == method) & (runs.setting == setting)
        depth = np.maximum(depth_under_pushes(runs.sent[mine], pushes_of_run(runs, method, setting)) - dead_zone, 0.0)
        offset = runs.end_effector_px[mine] - runs.circle_px[mine]
        for point, d, o, rise in zip(runs.sent[mine], depth, offset, runs.reported[mine, 2] - runs.sent[mine, 2], strict=True):
            row = np.zeros((2, 2 + 2 * runs_total))
            row[:, :2] = _plane_jacobian(camera, point) * d
            row[:, 2 + 2 * run : 4 + 2 * run] = np.eye(2)
            slide_rows.append(row)
            offsets.append(o)
            rise_row = np.zeros(1 + runs_total)
            rise_row[0], rise_row[1 + run] = d, 1.0
            rise_rows.append(rise_row)
            rises.append(rise)
    depths = np.array([r[0] for r in rise_rows])
    if not (depths > 0).any():
        raise ValueError(f"no touch of {methods} was sent beyond {dead_zone * 1e3:g} mm under the paper: nothing to fit")
    slide, slide_se, slide_rms = _least_squares(np.concatenate(slide_rows), np.concatenate(offsets), 2)
    give, give_se, give_rms = _least_squares(np.array(rise_rows), np.array(rises), 1)
    return ContactFit(
        slide, slide_se, float(give[0]), float(give_se[0]), len(depths), int((depths > 0).sum()), dead_zone, slide_rms, give_rms
    )
