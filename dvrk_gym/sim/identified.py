"""The paper's instrument as identified from the authors' real Phase I rows: every value, and where it came from.

The authors published the 1939 rows they kept in Phase I (:mod:`dvrk_gym.calibration.datasets`):
for each, the pose the dVRK reported and where the stereo endoscope saw the red tape. The
values here were fitted to those rows by ``python benchmarks/identify_instrument.py``
(:mod:`dvrk_gym.fidelity.identify`), on a training part (the first 70% of the rows, in
collection order) and checked on the held-out rest, before three mends to it: its priors
are Gaussian now, not Huber; the detector's share of the image-plane jitter counts the
stereo depth's noise, so the repeatability comes to 0; and the camera's rotation is fitted
as a turn of its start. The mended script's values differ (roll offset -5.35 degrees,
wrist stretch -0.071, settle lag 0.23, repeatability 0): a candidate instrument, for
which every simulated figure of the README would be measured again, set out with what it
does to the fidelity report in ``docs/fidelity.md`` ("The identification mended"). The figures quoted below are the script's before the
mends (4.3 minutes with ``--bootstrap 2`` on a busy 2-core machine, and about 30 s more
per replicate of the default 16). One value the rows cannot give, the red-tape detector's
right-image shift (:data:`TAPE_RIGHT_SHIFT_PX`), comes from the authors' records of the
runs behind the paper's calibration table (``python benchmarks/identify_tape_shift.py``).
``bias="paper"``
(:mod:`dvrk_gym.sim.robot.bias`), the default camera
(:func:`dvrk_gym.sim.endoscope.camera.default_camera_pose`), the red tape's place on the
jaws (:data:`dvrk_gym.sim.robot.body.MARKER`) and the red-tape detector
(:class:`dvrk_gym.sim.world.WorldConfig`) take their values from this module, and only from it.

Plain numbers only (SI units: metres, radians; pixels at 1920 x 1080 for the detector), so
that every part of ``sim/`` may import it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "CameraValues",
    "InstrumentValues",
    "DetectorNoiseValues",
    "CAMERA",
    "MARKER_OFFSET_M",
    "INSTRUMENT",
    "INSTRUMENT_SD",
    "OUTER_STRETCH_MAGNITUDE_RAD",
    "MARKER_DETECTION_NOISE",
    "TAPE_RIGHT_SHIFT_PX",
    "TAPE_ROWS_DEPTH_M",
    "WRIST_SETTLE_LAG",
    "FIT_RESIDUALS",
    "ContactValues",
    "PAPER_CONTACT",
]


@dataclass(frozen=True)
class DetectorNoiseValues:
    """The red-tape detector's error in each camera: a Gaussian core and rare outliers.

    Attributes:
        core_px: sd of the usual error on each of u and v, pixels at 1920 x 1080.
        outlier_px: sd of an outlying detection's error on each of u and v, pixels.
        outlier_probability: chance that a detection is an outlier.
        miss_probability: chance that the detector finds no tape in one camera's image
            although the tape is in view.
    """

    core_px: float
    outlier_px: float
    outlier_probability: float
    miss_probability: float


MARKER_DETECTION_NOISE = DetectorNoiseValues(core_px=0.816, outlier_px=3.408, outlier_probability=0.228, miss_probability=0.149)
"""Identified from the rows' left/right row differences. The authors triangulated with the
disparity ``|left - right|`` (row mismatch included) from whole-pixel detections, so each
row's depth and left pixel give back its whole-pixel horizontal disparity and row
difference exactly (with the authors' camera files: :data:`dvrk_gym.paper.ENDOSCOPE_FOCAL_PX`).
A rectified pair sees a point on one row, so the row difference is the difference of the
two cameras' detection errors, truncated to whole pixels: its histogram (row differences
0, 1, 2, ... px: 455, 677, 356, 186, 105, 64, 42, 22, 6, 10, 5 of the 1939 rows; 23% over
2 px) is fitted by maximum likelihood over the first 70% of the rows. The held-out 30% has
a little more 2-4 px and fewer 0 px differences than the fit predicts (chi-square p < 0.001:
the detector drifted during the collection), so these values are an average over it. The
same errors in u set the disparity's noise, 2.5 px RMS, which makes the depth noise: the
fidelity report's view-axis jitter checks it against the real rows. The miss probability
is matched to the share of rows kept: a simulated Phase I of the identified instrument (with
its settle lag, :data:`WRIST_SETTLE_LAG`, the authors' collector, a pause every 2 mm,
:data:`dvrk_gym.paper.PHASE1_STEP_M`, and the authors' search boxes,
:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`) whose detector never misses keeps 50.9% of
its rows, the real one kept 37% (1939 of 5256), and a miss in either camera loses the row,
so each camera misses 1 - sqrt(0.369 / 0.509) = 14.9% of the time. The boxes lose 30% of
the rows a detector searching the whole image keeps (73.2% of them without misses, so
29.0% misses; 30.0% with the simulator's earlier collector, a pause every millimetre; 30.4%
before the tape's right-image shift, :data:`TAPE_RIGHT_SHIFT_PX`: the 12 px gate, which
measures the right detection against where the grid's map sends the left one, drops a
little more of the shifted tape; 27.5% before the lag, which keeps more rows: the wrist's
orientations lag towards the last kept one).
Why the real detector lost those rows (lighting, its hue thresholds, a gross
mismatch the 12 px gate threw out) the rows do not say. This rate is an average, not how the
real robot lost its rows: they fall on the paper's yaws in the simulation's shares, but
within a yaw not at random: at yaw 0 and 20 to 30 degrees of pitch the real robot kept 0.13
of the rows the protocol commands there, the simulated one 0.36; at yaw 90 below -10
degrees 0.06 against 0.39. (A detector searching the whole image, missing 30.0% at random,
could keep at most 0.49 of any orientation, and the real robot kept more than that in
some; with the boxes, no band of the real robot's exceeds the 0.72 this rate allows.) And
no function of the line of sight in the tape's frame,
which is what decides what a rigid tape shows, gives the real robot's kept pitches back; a
function of the tape's whole orientation in the camera frame does
(``python benchmarks/fidelity_dropped_rows.py``). What the real detector's misses depended
on beyond the line of sight (the tape's turn about it: the light, the occluding links, the
detector's own filters; or the orientation whatever the line of sight, were the identified
lines of sight off) is not in the model."""


WRIST_SETTLE_LAG = 0.19
"""The share of each commanded wrist-pitch and wrist-yaw step that the motors have not made
when a move ends (:attr:`dvrk_gym.sim.robot.bias.BiasConfig.wrist_settle_lag`): the encoders,
and so the reported pose, lag the command. The real rows show it in their sequence
(``python benchmarks/fidelity_sequence.py``): returns to one commanded orientation are
reported 1.4 degrees of pitch apart, and rows taken at one pause report positions up to
1.6 mm apart, where a robot that reported its command would repeat it exactly. Matched to
the share of consecutive kept rows whose reported positions lie within 0.2 mm (real 0.0304)
with simulated Phase I collections of the identified instrument (the authors' collector and
search boxes) at lags 0.10, 0.15, ..., 0.35 (:func:`dvrk_gym.fidelity.settle_lag.match_settle_lag`):
shares 0.093, 0.046, 0.026, 0.025, 0.018, 0.016, which fall to the real one at 0.19 (linear
between 0.15 and 0.20; a detector searching the whole image gave 0.20, and with the
simulator's earlier collector, a pause every millimetre, 0.25). The collections use this
module's detector, whose misses are matched with the lag (:data:`MARKER_DETECTION_NOISE`);
the script gives back both values from them, so the two are consistent. The lag also
correlates the reported pitch from row to row, but far less than the real rows' 0.27
(0.05-0.08 over the grid): a joint-space lag becomes a pitch lag only while roll stays put."""


TAPE_RIGHT_SHIFT_PX = 2.47
"""How far left of the tape the red-tape detector's centroid lies in the right image, pixels
at 1920 x 1080 (:attr:`dvrk_gym.sim.endoscope.noise.DetectionNoise.right_shift_px`): it
widens the tape's disparity, so the tape, and only the tape, is triangulated nearer than it
is. The Phase I rows cannot tell this from a short stereo baseline (the depth scale of
:data:`CAMERA` holds both); the records of the table's runs can
(``python benchmarks/identify_tape_shift.py``, 6 to 14 minutes on a busy machine). The rigid body the authors
fitted to the tape's rows put the printed circles 7.2 mm under the jaws pushed onto them
(the mean over the five yaws of the median per yaw). The simulated rigid body, fitted to a
Phase I of the identified instrument and touched with ``dvrk-gym evaluate``'s seeds, unlifted
(``--protocol raw``), put them
1.7, 6.1, 8.4 and 10.8 mm under at shifts of 0, 2, 3 and 4 px; 7.2 mm is reached at 2.47 px
(linear between 2 and 3, on the unrounded means). The shift narrows what the 12 px gate
keeps, so the detector's misses were matched again with it (:data:`MARKER_DETECTION_NOISE`);
with them the script gives 1.8, 6.2, 8.5 and 10.8 mm, and 2.45 px; with the circles
touched in the authors' order (:data:`dvrk_gym.envs.grid_touch.TOUR`) 1.7, 6.1, 8.4 and
10.8 mm, and 2.46 px: 0.02 mm of dive from 2.47, a tenth of its spread over instruments at
one shift (instruments 1-3, not identified on, dive 7.2 to 7.5 mm at 2.46 px; the real
per-yaw medians -5.5 to -8.4, the simulated -5.5 to -8.2).
The authors' right-image tape detector was the looser one
(saturation and value from 70, not 90: ``_get_thresholded_image`` in their
``scripts/automatic_trajectory_collector.py``). With it the true baseline is 6.26 mm, 1.3%
longer than the 6.18 mm the authors triangulated with, not 4.7%."""

TAPE_ROWS_DEPTH_M = 0.19574
"""The real rows' median depth, metres: the median camera z of the 1939 rows (0.18649 m, as
the authors triangulated them) over the depth scale (:data:`CAMERA`). Where the tape's
right-image shift (:data:`TAPE_RIGHT_SHIFT_PX`) and the true baseline together put the tape
as the rows do (:func:`dvrk_gym.sim.endoscope.baseline.true_baseline_m`)."""


@dataclass(frozen=True)
class CameraValues:
    """The endoscope as the authors' triangulation saw the robot.

    Attributes:
        rotation_vector: T_base_leftcam's rotation as a rotation vector (axis times angle), rad.
        position_base_m: the left camera's optical centre in the base frame, metres.
        depth_scale: triangulated camera-frame positions are this times the true ones
            (the authors' stereo calibration against the truth), dimensionless.
    """

    rotation_vector: tuple[float, float, float]
    position_base_m: tuple[float, float, float]
    depth_scale: float


@dataclass(frozen=True)
class InstrumentValues:
    """The cable-driven instrument's parameters (:mod:`dvrk_gym.sim.robot.cables`), SI units.

    Attributes:
        homing_offsets: (6,) constant joint offsets, rad / m (insertion in m).
        outer_stretch_rad: (2,) signed amplitude A of the outer yaw / pitch stretch
            ``A tanh((q - q_unloaded) / s)``, rad.
        wrist_stretch: signed compliance of the wrist cables (the sign turns the nominal
            coupling round), dimensionless.
        backlash_outer_rad: hysteresis gap of outer yaw and pitch, rad.
        backlash_wrist_rad: hysteresis gap of roll, wrist pitch and wrist yaw, rad.
        repeatability_m: RMS tip scatter of repeated moves to one command, across the
            shaft (the rotary joints'), m.
    """

    homing_offsets: tuple[float, float, float, float, float, float]
    outer_stretch_rad: tuple[float, float]
    wrist_stretch: float
    backlash_outer_rad: float
    backlash_wrist_rad: float
    repeatability_m: float


CAMERA = CameraValues(
    rotation_vector=(0.1907772, -2.9697524, 0.0695448),
    position_base_m=(0.0645950, 0.0697141, 0.0170019),
    depth_scale=math.exp(-0.0484216),
)
"""Fitted (with the rest of the deterministic parameters). The camera sits about 0.18 m
above the paper and looks down 9.8 degrees from the vertical; the depth scale 0.953 (bootstrap
sd 0.010) says the authors' triangulation put the tape 4.7% nearer the lens than it was.
A baseline short of the true one does that to everything the camera sees, a tape detector
whose right-image centroid lies left of the tape to the tape alone; the rows hold only the
tape and cannot tell the two apart. The records of the table's runs split it: the detector's
shift (:data:`TAPE_RIGHT_SHIFT_PX`) with a true baseline 1.3% longer than the authors' 6.18 mm
(:func:`dvrk_gym.sim.endoscope.baseline.true_baseline_m`). A scale in the robot's kinematics
would do the same to these rows; the camera's is the one free parameter that does it for all
three axes at once. The identification scales the tape's depth by this one number; the
simulator, with the shift, sees the tape within 0.5 mm of it over the rows' depths (5th to
95th percentile; :func:`~dvrk_gym.sim.endoscope.baseline.true_baseline_m`), against 5 mm of
stereo depth noise. Fitting the camera with the shift in the model is not done."""

MARKER_OFFSET_M = (-0.0012731, 0.0079513, -0.0011300)
"""The red tape's centre as the fit sees it, a point in the wrist-yaw frame, metres: 7.95 mm
(bootstrap sd 0.43) along the closed jaws from their pivot (the tips are at 10 mm), 1.27 mm
to their -x side and 1.13 mm to their -z side. The camera-and-tape fit alone puts it 5.6 mm
along the jaws; the cable terms move it out to 8.0 mm and cut the held-out residual
(FIT_RESIDUALS). The simulated tape (:data:`dvrk_gym.sim.robot.body.MARKER`) lies 7.95 mm
along the jaws; which sides of the jaws it covers comes from which orientations the real
rows kept, and those say the +x side, not the -x side this point lies towards: a fixed point
cannot follow a tape whose visible part changes with the view, and the fit's x absorbs
something else (a fit with the tape's visible sides modelled left the x at -2 mm and the
residuals as they are)."""

INSTRUMENT = InstrumentValues(
    homing_offsets=(0.0, 0.0, 0.0017710, -0.1112138, -0.0157306, 0.0),
    outer_stretch_rad=(-0.0064190, -0.0049532),
    wrist_stretch=-0.0861424,
    backlash_outer_rad=0.0,
    backlash_wrist_rad=0.0604368,
    repeatability_m=0.001038,
)
"""Fitted: homing offsets of insertion (1.8 mm), roll (-6.4 deg) and wrist pitch (-0.9
deg), under Gaussian priors of 1 mm and 1 degree (the outer yaw and pitch offsets turn the
whole arm about the RCM, which the camera pose absorbs; the wrist-yaw offset turns the tape
about the pivot, which the tape's position absorbs: both 0). The wrist-pitch offset trades
with the tape's height on the jaws: held at -15 or -30 degrees the fit is as good, with the
tape point at z = 3.2 or 8.2 mm, off the jaws (their faces are at +-1.3 mm); the prior
keeps it near -1 degree, with the tape point at the jaws' -z face, where the simulated tape
lies (``python benchmarks/fidelity_visibility.py --camera-fit``). Outer stretch -0.37 / -0.28
degrees (not the 2.6 degrees once tuned to the paper's table); wrist stretch -0.086 (the
sign: opposite to the nominal coupling); backlash 3.5 degrees in the wrist, none in the
outer joints. Repeatability: not fitted, but what the real rows' sample-to-sample jitter in
the image plane (1.02 mm per axis) leaves after the fitted model's own jitter over the same
rows (0.70 mm, mostly the wrist backlash) and the detector's (0.16 mm, which leaves out
the stereo depth's share, 0.90 mm with it: see the module's docstring): 0.73 mm per axis,
1.04 mm across the shaft, scattered by the five rotary joints (none by the insertion stage:
the rows' jitter along the view axis is the stereo depth noise's alone, so they show no
scatter along the shaft; :func:`dvrk_gym.sim.robot.cables.repeatability_std`). The rows
cannot tell true repeatability from hysteresis over the moves they do not record (63% of
the poses were dropped); either way no calibration can learn it."""

OUTER_STRETCH_MAGNITUDE_RAD = max(abs(a) for a in INSTRUMENT.outer_stretch_rad)
"""The ``paper`` preset's outer stretch magnitude; the identified amplitudes are gains on it."""

INSTRUMENT_SD = InstrumentValues(
    homing_offsets=(0.0, 0.0, 0.0011952, 0.0123063, 0.0046662, 0.0),
    outer_stretch_rad=(0.0010187, 0.0009114),
    wrist_stretch=0.0209368,
    backlash_outer_rad=0.0,
    backlash_wrist_rad=0.0048459,
    repeatability_m=0.0,
)
"""sd of each value over a moving-block bootstrap of the training rows (blocks of 50 rows,
16 replicates): the spread with which ``bias_seed`` >= 1 draws other instruments around the
identified one (:func:`dvrk_gym.sim.robot.bias.identified_instrument`), instruments these
rows could not tell apart from it. Zero where a value was not fitted."""

FIT_RESIDUALS = {
    "camera and tape, train": (8.15, 8.26, 2.69),
    "camera and tape, held out": (9.35, 8.35, 2.56),
    "full, train": (6.39, 6.43, 2.61),
    "full, held out": (7.47, 6.76, 2.54),
}
"""RMS pixel residuals (left u, left v, disparity) of the fit on the 1357 training rows and
the 582 held-out ones, for the camera and tape alone and for the full model; in the camera
frame the full model leaves 0.94 / 1.16 / 6.39 mm (x, y, z) on the held-out rows. What is
left is the detector's noise (the disparity's: 2.5 px), the repeatability, and structure
none of these terms has (a random forest on pose and orientation explains about a third
of it)."""


@dataclass(frozen=True)
class ContactValues:
    """How the paper under the grid gives way when the jaws are sent under it.

    Attributes:
        slide_per_depth: (2,) how far the jaws slide along the robot's x and y per metre
            the command goes under the paper, metres per metre.
        give: the share of that depth by which the arm stops short of its command (the
            reported height lies ``give * depth`` over the command), dimensionless.
    """

    slide_per_depth: tuple[float, float]
    give: float


PAPER_CONTACT = ContactValues(slide_per_depth=(-0.710, 0.232), give=0.390)
"""Fitted to the authors' records of the rigid body's table runs (its 175 touches at the five
fixed yaws, 93 of them sent under the jaws pushed onto the paper that day, up to 10 mm) by
``python benchmarks/identify_contact.py`` (:func:`dvrk_gym.fidelity.contact.fit_contact`):
slide (-0.710, 0.232) m/m, standard errors 0.042 each, 0.75 mm of slide per mm of depth,
right and a little down in the left image; give 0.390 (0.008). The touches sent over the
paper show neither (slopes 0.0 for the rigid body). The networks' runs, which the fit never
saw, do not confirm it: they were sent hardly under the paper (median 0.4 mm of their
touches under it); their give is 0.275 (DNN, 0.026) and 0.386 (DNN+RF, 0.028), and their
slide, (0.05, 0.61) m/m (0.13), points along y, not x. Their offsets and reported heights go
with the height they were sent at over the paper too (DNN+RF: -12.7 px/mm along u, -0.126
in the reported height), where nothing touches, so at a few tenths of a millimetre their
other errors swamp a slide. The line is the rigid body's, measured from 1 to 10 mm; the
simulator extends it to every depth."""
