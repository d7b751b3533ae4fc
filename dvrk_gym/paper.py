"""Every number taken from the paper, and where the real data come from.

The paper: D. Seita, S. Krishnan, R. Fox, S. McKinley, J. Canny, K. Goldberg, "Fast and
Reliable Autonomous Surgical Debridement with Cable-Driven Robots Using a Two-Phase
Calibration Procedure", ICRA 2018. Where a number comes from the authors' code release
instead (:data:`AUTHORS_CODE`), its note says so. Each note names the part of the paper it
comes from and its unit; lengths the simulator uses directly are given in metres, angles in
degrees as the paper gives them (the simulator converts), errors in the units of the
paper's tables (pixels, mm, mm^2).

This is the bottom layer of the package: it imports nothing, so any module may import it.
The keys of the tables are the package's names: calibrators ``"rbt"``, ``"dnn"``,
``"dnn+rf"`` (:data:`METHOD_LABELS`), fragments ``"pumpkin_seed"``, ``"raisin"``
(:data:`FRAGMENT_LABELS`), debridement phases as ``Debridement-v0`` names them.
"""

from __future__ import annotations

CITATION = (
    "D. Seita, S. Krishnan, R. Fox, S. McKinley, J. Canny, K. Goldberg. Fast and Reliable Autonomous Surgical "
    "Debridement with Cable-Driven Robots Using a Two-Phase Calibration Procedure. ICRA 2018."
)
AUTHORS_CODE = "https://github.com/DanielTakeshi/debridement-code"
"""The authors' code release: their data, ROS camera files and robot settings."""

# ---------------------------------------------------------------------------- names
METHOD_LABELS: dict[str, str] = {"rbt": "RBT", "dnn": "DNN", "dnn+rf": "DNN+RF"}
"""The paper's three calibration methods (rows of its calibration table): the package's
name for each, and the paper's label. RBT: a rigid body transform per yaw; DNN: the Phase I
network; DNN+RF: the network plus the Phase II residual forests."""
FRAGMENT_LABELS: dict[str, str] = {"pumpkin_seed": "pumpkin seeds", "raisin": "raisins"}
"""The paper's two kinds of fragment (its debridement table): the package's name, the paper's word."""

# ---------------------------------------------------------------------------- Phase I
PHASE1_TRAJECTORIES = 57
"""Phase I (coarse calibration): random trajectories from the four workspace corners."""
PHASE1_RAW_SAMPLES = 5256
"""Phase I: samples recorded over the 57 trajectories."""
PHASE1_KEPT_SAMPLES = 1939
"""Phase I: samples kept, where both cameras saw the red marker at the same place (37%)."""
PHASE1_POSES_PER_TRAJECTORY = -(-PHASE1_RAW_SAMPLES // PHASE1_TRAJECTORIES)
"""Commanded poses per Phase I trajectory here: 93, the raw samples over the trajectories
rounded up (the paper gives only the totals); 57 x 93 = 5,301 poses."""
PHASE1_STEP_M = 0.002
"""Phase I: the tool pauses every 2 mm along a trajectory, metres. The paper's text says
about every millimetre; the authors' collector (``scripts/automatic_trajectory_collector.py``
of :data:`AUTHORS_CODE`, as of its last change, commit 410b8c2) pauses every 20 interpolation
steps of 0.1 mm, and their real rows
agree: a trajectory's own orientation, commanded first at every pause, recurs 1.96 to 2.00 mm
(median, 1 to 4 rows later) from where it was last reported."""
PHASE1_CORNER_HEIGHT_M = 0.005
"""Phase I (the authors' collector): each trajectory starts at a corner of the workspace this
high over the paper (the plane through the four corners where the arm was put on the paper
by hand), metres."""
PHASE1_TARGET_HEIGHT_M = 0.001
"""Phase I (the authors' collector): each trajectory heads for a random target this high over
the paper, metres."""
PHASE1_ROTATIONS_PER_PAUSE = 3
"""Phase I: random rotations commanded at each pause."""
PHASE1_YAW_RANGE_DEG = (-90.0, 90.0)
PHASE1_PITCH_RANGE_DEG = (-15.0, 25.0)
PHASE1_ROLL_RANGE_DEG = (-180.0, -150.0)
"""Phase I: each rotation's yaw, pitch and roll are uniform in these ranges, degrees."""

# ---------------------------------------------------------------------------- the network and the model search
DNN_HIDDEN_LAYERS = 3
DNN_UNITS = 300
DNN_ACTIVATION = "relu"
DNN_EPOCHS = 1000
"""Phase I network f: (cx, cy, cz, yaw, pitch, roll) -> (bx, by, bz): 3 hidden layers of 300
ReLU units, Adam on the squared L2 loss, 1000 epochs."""
SEARCH_FOLDS = 10
"""The model search: k of the k-fold cross-validation of every candidate."""
SEARCH_MM2: dict[str, float] = {"DNN_u300_h3_relu": 2.06, "DNN_u300_h1_sigmoid": 1.21}
"""The model search (24 nets: 1-4 layers x 30 or 300 units x ReLU, sigmoid, tanh; with linear
maps and forests), 10-fold CV mean squared L2 error on the real Phase I data, mm^2: the
chosen net (3 x 300 ReLU) and the best (1 x 300 sigmoid)."""
AUTHORS_CV_MM2: dict[str, float] = {"linear": 3.76, "forest": 5.03, "3 x 300 ReLU": 1.74}
"""The authors' code on the real Phase I data (10-fold CV, mean squared L2 error, mm^2):
linear regression, a random forest (1000 trees) and their 3 x 300 ReLU net (about 1.74)."""

# ---------------------------------------------------------------------------- Phase II
PHASE2_YAWS_DEG = (-90.0, -45.0, 0.0, 45.0, 90.0)
"""Phase II (fine calibration): the five yaws, degrees; a fragment's yaw is rounded to the nearest."""
GRID_CIRCLES = 35
"""The printed calibration grid: circles whose centres the gripper is taken to."""
PHASE2_TOUCHES = GRID_CIRCLES * len(PHASE2_YAWS_DEG)
"""Phase II: one touch, corrected by a person, per circle and yaw (175)."""
RESIDUAL_FOREST_TREES = 100
"""Phase II: trees of each per-yaw residual random forest (default depth)."""
PITCH_AT_YAW_EXTREMES_DEG = (0.0, 10.0)
ROLL_AT_YAW_EXTREMES_DEG = (-170.0, -165.0)
"""The authors' code: pitch and roll follow from yaw, linearly from yaw -90 to +90 degrees
(pitch 0 -> 10, roll -170 -> -165), degrees."""

# ---------------------------------------------------------------------------- the calibration table
CALIBRATION_SETTINGS = ("yaw -90", "yaw -45", "yaw 0", "yaw 45", "yaw 90", "random")
"""The columns of the table "Calibration Error Results (In Pixels)": five fixed yaws, and a
random yaw per circle."""
CALIBRATION_PIXELS: dict[str, tuple[float, ...]] = {
    "RBT": (39.9, 53.6, 52.0, 72.0, 44.1, 47.1),
    "DNN": (26.7, 28.3, 22.7, 21.5, 22.5, 23.1),
    "DNN+RF": (10.5, 14.2, 12.8, 12.1, 8.9, 14.7),
}
"""Table "Calibration Error Results (In Pixels)": mean error over the 35 circles per setting
(:data:`CALIBRATION_SETTINGS` order), pixels of the 1920 x 1080 left image."""
CALIBRATION_MEAN_PX: dict[str, float] = {"RBT": 51.45, "DNN": 24.13, "DNN+RF": 12.20}
"""The same table: each method's mean over all settings, pixels."""
CALIBRATION_MEAN_MM: dict[str, float] = {"RBT": 4.55, "DNN": 2.14, "DNN+RF": 1.08}
"""The same means in millimetres, as the paper converts them (:data:`PX_PER_MM`)."""
PX_PER_MM = 11.3
"""The paper's scale of the left image over the workspace, pixels per millimetre (focal
length 2144 px x 1 mm / 190 mm)."""
TABLE_Z_BAND_M = (-0.180, -0.168)
"""The authors' code, ``scripts/click_and_crop_v3.py`` (which measured every cell of the
table): the band of the robot's frame a prediction's height is clipped into before the move,
metres. The clip came in during the rigid body's runs (its author's note at version 43: "I
wised up and put in minimum and maximum commands for the z-coordinate"); which runs it
clipped: :data:`TABLE_CLIPPED`."""
TABLE_CLIPPED: dict[str, tuple[bool, ...]] = {
    "RBT": (True, True, False, False, False, True),
    "DNN": (False,) * 6,
    "DNN+RF": (False,) * 6,
}
"""Whether each run of the table clipped its heights into :data:`TABLE_Z_BAND_M`
(:data:`CALIBRATION_SETTINGS` order): the rigid body's versions 43-45 (yaw -45, -90, random);
not its first three, nor the network's runs five days before (their records send heights
above the band)."""
TABLE_PAPER_Z_M = -0.1677
"""The authors' code, ``config/mapping_results/manual_params_matrices_v00.txt``: the robot's
reported height with its jaws pushed onto the grid's circles (mean of 36), metres; the top of
:data:`TABLE_Z_BAND_M` lies 0.3 mm under it."""
TABLE_LIFT_MM: dict[str, tuple[float, ...]] = {
    "RBT": (8.0, 9.0, 8.0, 6.0, 4.0, 8.0),
    "DNN": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "DNN+RF": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
}
"""The authors' code, ``images/visuals/README.md`` (the runs whose means are the table's,
within 0.1 px: the network's versions 20-25, with the forests 30-35, the rigid body's 40-45):
the ``--z_offset`` each run added to the height, clipped in the runs that clipped
(:data:`CALIBRATION_SETTINGS` order), mm. The rigid body's runs were lifted 4 to 9 mm, their
author noting that height was a main reason for its low performance; the network's example
call (``click_and_crop_v3.py``, version 23) gives 0, and its other runs record no offset (the
script's default is 0)."""
TABLE_PUSH_ROUND: dict[str, int] = {"RBT": 1, "DNN": 0, "DNN+RF": 0}
"""The round of Phase II pushes in the authors' records made on the day of each method's runs
(:func:`dvrk_gym.calibration.datasets.load_paper_table_runs`, ``push_round``): the network's
and DNN+RF's on 1 September 2017, the rigid body's on 6 September. The reported height of the
jaws on the paper moved by about 1.2 mm between the two."""

# ---------------------------------------------------------------------------- debridement
DEBRIDEMENT_TRIALS = 15
"""Debridement: trials per cell of the table (method x fragment)."""
FRAGMENTS_PER_TRIAL = 8
"""Debridement: fragments on the phantom per trial, at any orientation."""
DEBRIDEMENT_PICKS_PER_CELL = DEBRIDEMENT_TRIALS * FRAGMENTS_PER_TRIAL
"""Debridement: picks judged per cell (120)."""
FRAGMENT_MIN_GAP_M = 0.003
"""Debridement: fragments lie at least 3 mm apart, metres."""
DEBRIDEMENT_RESULTS: dict[tuple[str, str], dict[str, int]] = {
    ("dnn", "pumpkin_seed"): {"success": 73, "A": 34, "B": 13, "C": 0},
    ("dnn+rf", "pumpkin_seed"): {"success": 110, "A": 1, "B": 9, "C": 0},
    ("dnn", "raisin"): {"success": 113, "A": 4, "B": 0, "C": 3},
    ("dnn+rf", "raisin"): {"success": 119, "A": 1, "B": 0, "C": 0},
}
"""The debridement table: outcomes of 15 trials x 8 fragments per (method, fragment), picks.
A: a calibration miss; B: the fragment slipped though the calibration was accurate; C: a
raisin pulled out by one tip."""
TRIAL_S = 58.0
"""Debridement: about this many seconds per 8-fragment trial."""
TIME_PER_FRAGMENT_S = (7.2, 7.3)
"""Debridement: seconds per fragment, as the paper gives the range."""
VIDEO_FPS = 25.0
"""The frame rate of the paper's phase timing, frames per second."""
DEBRIDEMENT_PHASE_FRAMES: dict[str, float] = {
    "to_seed": 26.0,
    "lower": 16.1,
    "grip": 37.5,
    "raise": 24.0,
    "to_receptacle": 42.1,
    "drop_and_rotate": 38.5,
}
"""Debridement: mean duration of each phase of a pick, in order, frames at 25 fps."""
DEBRIDEMENT_PHASE_S: dict[str, float] = {name: frames / VIDEO_FPS for name, frames in DEBRIDEMENT_PHASE_FRAMES.items()}
"""The same, seconds (7.37 s a fragment in all)."""
PRIOR_TIME_PER_FRAGMENT_S = (15.8, 91.8)
"""The two earlier autonomous debridement systems the paper compares with, seconds per fragment."""

# ---------------------------------------------------------------------------- the fragments
PUMPKIN_SEED_SIZE_MEAN_M = (0.0124, 0.0068, 0.0024)
PUMPKIN_SEED_SIZE_SD_M = (0.0008, 0.0003, 0.0003)
"""The paper's fragment table, pumpkin seeds: (length, width, thickness) mean and standard
deviation, metres (12.4+-0.8 x 6.8+-0.3 x 2.4+-0.3 mm)."""
RAISIN_SIZE_MEAN_M = (0.0123, 0.0059, 0.0042)
RAISIN_SIZE_SD_M = (0.0015, 0.0011, 0.0005)
"""The paper's fragment table, raisins: (length, width, thickness) mean and standard
deviation, metres (12.3+-1.5 x 5.9+-1.1 x 4.2+-0.5 mm)."""

# ---------------------------------------------------------------------------- the robot and the endoscope
MAX_TOOL_SPEED_M_S = 0.06
"""The tool's top speed, about 6 cm/s, m/s (the authors' code: a 10 cm move at "fast" took 1.49 s)."""
ENDOSCOPE_RESOLUTION_PX = (1920, 1080)
"""The stereo endoscope's images, (width, height), pixels (the authors' ROS camera files)."""
ENDOSCOPE_FOCAL_PX = 2144.0564
"""The rectified focal length, pixels: P[0, 0] = P[1, 1] of both cameras in the authors' ROS
camera files (``config/camera_info_matrices/left.p``, ``right.p`` of :data:`AUTHORS_CODE`,
read as text). Every row of the real data reprojects with it to whole pixels (to 1e-8 px)."""
ENDOSCOPE_PRINCIPAL_POINT_PX = (1116.71052, 599.58294)
"""The rectified principal point (cx, cy) of both cameras, pixels (P[0, 2], P[1, 2] of the
same files)."""
ENDOSCOPE_BASELINE_M = 13.24186 / 2144.0564
"""The stereo baseline the authors triangulated with, metres (6.176 mm): -P[0, 3] / P[0, 0]
of the right camera's file (P[0, 3] = -13.24186 px m)."""
MARKER_GATE_PX = 12.0
"""The authors' Phase I cleaning rule: a row is kept when both cameras found the red tape
and the right detection lies less than this from where an affine map fitted to the grid
circles sends the left one, pixels at 1920 x 1080 (``is_this_clean`` in
``scripts/automatic_trajectory_collector_part2.py`` of :data:`AUTHORS_CODE`)."""
MARKER_SEARCH_BOXES_PX: tuple[tuple[int, int, int, int], tuple[int, int, int, int]] = ((675, 50, 750, 750), (600, 75, 750, 750))
"""The image regions the authors' red-tape detector searched, (u, v, width, height) of the
left and the right rectified image at 1920 x 1080, pixels: ``lx, ly, lw, lh`` and ``rx, ry,
rw, rh`` of ``autolab/data_collector.py`` in :data:`AUTHORS_CODE`. Their Phase I collector
(``_get_contour`` of ``scripts/automatic_trajectory_collector.py``) kept only a blob whose
whole-pixel centroid lay strictly inside, and found no tape otherwise. Every one of the 1939
real rows' detections does (left u 684-1422, v 75-798; right u 614-1349): where the tape
appeared outside, the row was lost."""
MARKER_MEDIAN_KERNEL_PX = 9
"""The authors' red-tape detector median-filters the image and the thresholded mask with
this kernel (pixels at 1920 x 1080) before it takes the largest contour's centroid,
truncated to whole pixels (``_get_thresholded_image``, ``_get_contour`` of
``scripts/automatic_trajectory_collector.py``)."""
ENDOSCOPE_HEIGHT_M = 0.19
"""The endoscope sits 7.5 in (19 cm) above the workspace, metres."""

# ---------------------------------------------------------------------------- the real data
REAL_PHASE1_ROWS = PHASE1_KEPT_SAMPLES
"""Rows of the authors' cleaned Phase I data (the 1939 kept samples)."""
REAL_PHASE1_FILES = ("plotting/data/X_train.npy", "plotting/data/y_train.npy")
"""Where the real Phase I data lie in the authors' code release (:data:`AUTHORS_CODE`):
X = (cx, cy, cz) mm in the left camera frame and (yaw, pitch, roll) degrees; y = the
reported (bx, by, bz) mm in the base frame."""
REAL_PHASE1_LICENCE = "MIT"
"""The licence of the authors' code release, which covers the data; its text travels with
the copy in the package (``dvrk_gym/data/seita2018_phase1/LICENSE``)."""
REAL_PHASE1_PACKAGE_DIR = ("data", "seita2018_phase1")
"""Where the package keeps its copy of the real data, relative to ``dvrk_gym``."""
REAL_PHASE1_X_RANGE_M = (0.005, 0.070)
REAL_PHASE1_Y_RANGE_M = (0.011, 0.074)
REAL_PHASE1_Z_RANGE_M = (-0.170, -0.158)
"""The span of the real data's reported base positions (bx, by, bz), metres: where the
paper's workspace lay (base frame, origin at the remote centre of motion)."""
REAL_TABLE_TOUCHES = 630
"""Touches in the authors' records of their calibration table's runs: 3 methods x 6 settings x
35 circles (``config/calibration_results/data_vXY.p``, versions 20-25, 30-35, 40-45)."""
REAL_TABLE_PUSHES = 350
"""Phase II records of the same days: 2 rounds x 5 yaws x 35 circles, the robot's reported pose
before and after a person pushed its jaws onto a circle (``data_human_guided_vXY.p``, versions
20-24 and 40-44)."""
REAL_TABLE_PACKAGE_DIR = ("data", "seita2018_table_runs")
"""Where the package keeps its copy of those records, converted to one npz, relative to
``dvrk_gym`` (same licence: :data:`REAL_PHASE1_LICENCE`)."""
