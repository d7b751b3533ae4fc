"""Our three envs beside panda-gym's, stepped in one process with seeded random actions.

Run: python benchmarks/bench_peers.py  [--steps 1000] [--picks 16] [--delta-steps 100] [--rounds 5] [--resolution 1920 1080]
     python benchmarks/bench_peers.py --profile dvrk_gym/Debridement-v0 [--picks 24]  (cProfile of one env's steps)
Needs panda-gym (the ``bench`` extra): pip install -e ".[bench]", or pip install panda-gym==3.0.7.
With --steps 500 --picks 8 it took 4 minutes on the shared 2-core machine (load average 13-18).

Prints, for GridTouch-v0, CalibrationExploration-v0, Debridement-v0 (one step is one pick;
and in delta mode, one step a 0.1 s motion of the arm and jaws, the RL interface),
PandaReach-v3 and PandaPickAndPlace-v3: steps per wall second; the ratio to PandaReach-v3's,
taken round by round (each round's rate over PandaReach-v3's in the same round), as the
median and the range over the rounds, by wall time and by the process's CPU time; and two
real-time factors: the robot's clock (seconds of robot time per wall second: a GridTouch
move or a Debridement move through free space is placed at once and advances the clock by
its duration, with no physics stepped) and the physics integrated (``stepSimulation``'s
seconds per wall second: GridTouch-v0 and CalibrationExploration-v0 step none, Debridement-v0
about 600 steps of 1/240 s a pick; every Panda step integrates its 0.04 s). So GridTouch-v0's
ratio compares a kinematic env (inverse kinematics, the cable model, the contact search, the
stereo view of the touch) with a dynamics simulation of the same kind of reaching task.
Each env is made with ``gym.make`` (so with Gymnasium's wrappers, as a user has it), reset
with the seed, and stepped with random actions from its seeded action space; an episode that
ends is reset, and the reset counts in the time. The envs take turns, ``--rounds`` times, in
the reverse order every other round, so a change in the machine's load hits all of them alike.

Targets (issue 18): GridTouch-v0 at least 2x PandaReach-v3's steps/s; Debridement-v0 toward
10 picks/s.

Profiles (cProfile and timers, on the 2-core machine shared with other jobs, load average
8-19; issue 18):

* GridTouch-v0, a step and its reset, before: about 14 inverse kinematics, 13 cable model
  and 13 forward kinematics evaluations (the contact search and the simulated person's
  correction each iterate on IK -> cables -> touch point; 80% of the time). Per evaluation
  the cost was numpy's overhead on 3- to 6-element arrays, not arithmetic: each link
  transform built from nested lists with its own cos/sin of constant twists
  (``dh_transform``, the top line of the profile), the pose checks (``np.linalg.det``,
  ``np.eye``), joint checks looping over elements, the cable state copied out and back per
  evaluation, ``np.linalg.lstsq``'s wrapper in the gravity sag (7%), a tool rotation
  (cos/sin of yaw, pitch, roll) rebuilt for every evaluation of one yaw, the reported pose's
  FK recomputed five times a step, scipy's ``Rotation.from_matrix`` in every move's plan,
  and ``BulletClient.__getattr__`` making a ``functools.partial`` per pybullet call.
  After: a chain's transforms built at once from arrays made once per DH table, checks
  vectorised or in Python floats, the cable model peeked without copying its state, one
  rotation per yaw, the reported pose remembered per joint vector, the contact search's
  first point measured once, lstsq's LAPACK call without its wrapper, scipy's angle only
  when a bound on it could set a move's duration, each pybullet function bound once. Whole
  process CPU for 1,500 steps and resets, old and new code in turn: 8.06 s -> 5.17 s
  (0.69 s of it start-up). Every number is the same bit for bit: the same numpy
  operations on the same values (tests/test_fast_paths.py compares each fast path with the
  code it replaced); ``dvrk-gym reproduce --quick`` gives the same results.json. Left, in
  order: ``_solve_branch``'s own arithmetic, ``dh_transforms``, the 4x4 products of the
  chains, ``_least_squares``, ``set_joints`` (eight ``resetJointState`` calls: one
  ``resetJointStatesMultiDof`` call was faster but moved a fragment in a debridement trial,
  so it was not kept). Getting to 2x PandaReach-v3 would take fewer numpy calls per
  evaluation than the same operations allow, that is, other roundings (and other numbers).
* Debridement-v0, one pick (about 600 physics steps of 1/240 s: lowering, gripping,
  raising and the drop step physics; the moves to the fragment and to the receptacle are
  free-space teleports), before: rendering for the fragment observation 25-30% (two
  coarse renders and two windows per fragment seen; left to the rendering work of issue
  18), ``stepSimulation`` 11-14%, the gripper's Python per physics step (driving the
  joints, contact sensing, speed limits, grasp tests) about 30%, IK and cables of the
  stepped moves' waypoints about 25%. After: the same physics with the per-step and
  per-waypoint overheads cut as for GridTouch: 8 picks at 1920 x 1080, whole process CPU
  3.21 s -> 2.88 s (about 1 s of it start-up and the reset). Fewer or longer physics steps
  were not taken: every stepped phase has the jaws near, on or holding a fragment, and the
  fragments on the paper are stepped all along, so any change moves the outcomes.

Timers on a quiet 2-core machine (2026-11-23, after the above; each method of the env
wrapped with ``time.perf_counter``, 2,000 steps and resets with seeded random actions): a
GridTouch-v0 step and its reset took 2.13 ms, of which the simulated person's correction
0.64 ms (three IK -> cables -> touch point evaluations, about 0.2 ms each), the two moves
0.50 ms, the contact search 0.31 ms, the reset 0.33 ms (0.10 of it the stereo view of the
touch point, as in the step), the observation 0.04 ms and the wrappers and info the rest.
PandaReach-v3 stepped at 906/s in a run of this script the same hour (GridTouch-v0 457/s,
0.50x; Debridement-v0 4.0 picks/s). Every part left is the same few numpy evaluations on
3- to 6-element arrays; the 2x target needs them compiled or written in scalars, whose
roundings differ (every figure would be made again).

Float paths (2026-11-25, issue 18; load average 7-9 from a ``dvrk-gym reproduce`` on both
cores, so ratios within one run): a bit-for-bit scalar path is not possible here, because
numpy's 3x3 / 4x4 products go to OpenBLAS, whose kernel fuses multiply-adds (all 4,800
elements of 300 random products matched an FMA chain; plain Python sums about half), Python
3.11 has no exact fma, and np.arctan2 / np.hypot / np.tanh differ from math's in the
last bit on a few percent of inputs (np.sin / np.cos did not). So GridTouch-v0's touch
evaluations (the contact search, the simulated person's correction, the reset's lift) and
its two moves' inverse kinematics and true touch points run in Python floats
(``ik.inverse_kinematics_floats``, ``ik.touch_point_floats``,
``CableModel.peek_true_joints_floats``; numpy where a pose is clamped or singular); the
moves themselves (cables, physics, reported pose) are untouched, and the other envs do not
use these paths. An evaluation took 29 us against about 120 us (timeit, same process).
Differences over 2,100 seeded steps (yaw 0 and random) against the numpy path: observations,
goals, rewards and successes the same; true tip, reported position and correction at most
1.7e-16 m, pixel error 4.5e-13 px, mm error 1.1e-13 mm, simulated time 2.9e-14 s;
CalibrationExploration-v0 and Debridement-v0 bit for bit the same (tests/test_float_paths.py
bounds each path's difference). ``python benchmarks/bench_peers.py --steps 500 --picks 4
--rounds 3``, old code then new, minutes apart: GridTouch-v0 0.47x -> 0.76x PandaReach-v3, and
0.41x -> 0.77x in a second pair (0.85x in a third run of the new code, its PandaReach slow)
(timers: a step and its reset 2.27 -> 1.44 ms, the correction 0.73 -> 0.25 ms, the contact
search 0.31 -> 0.10 ms). Left (cProfile, 2,000 steps): the two moves (cable model in numpy,
the planned move's FK, eight ``resetJointState`` calls each: about 0.27 ms), the touch
evaluations still (7.4 a step, the correction iterating 5.3 times on average, at 29 us:
inverse kinematics 10, cables 9, touch point 6.5), the stereo view of the touch point (twice
a step) and the reset; 2x needs most of these in floats or compiled, and the moves in floats
would change the other envs' numbers.

Moves, reset and stereo view in floats (2026-11-25, later; quiet machine, load average
0.7): a move cost 133 us (timeit: cable model 35, the end pose's FK 19, ``set_joints`` 18
of which eight ``resetJointState`` calls 12, the plan 7, the rest array handling) and the
touch point's projection, noise and triangulation 67 us a step. GridTouch-v0 alone now
takes ``DvrkWorld.move_joints_floats`` (``CableModel.true_joints_floats``,
``ik.forward_kinematics_floats``), ``reset_robot(floats=True)`` and the camera's and pixel
noise's float methods, so the other envs keep their numbers; on that path ``set_joints``
sets all eight joints in one ``resetJointStatesMultiDof`` call (2.2 us). Not elsewhere: as
the note above found for ``set_joints`` then, a review found the batched call in the world's reset
moved a fragment once a debridement pick stepped physics (0.04 mm after four oracle picks;
the joint state is the same, PyBullet's collision bookkeeping is not). The reported pose's FK stays
numpy's: its bits reach the simulated person's correction and so the residual forests.
Over 9,000 seeded steps and resets (three instruments, yaw 0 and random) the observations,
rewards, successes, reported positions and corrections are the numpy path's bit for bit
(the cables' plays are np.clip's values, reproduced exactly); tip, pixel and mm errors and
simulated time within 8e-13. Interleaved runs of 2,000 steps and resets: 793 / 799 ->
1,115 / 1,117 steps/s; this script, same hour: GridTouch-v0 0.82x -> 1.17x PandaReach-v3
(1.15x after the review's mends, which leave the reported pose's FK to numpy).
What is left (cProfile): the seven touch evaluations (inverse kinematics about 12 us each,
the chain's link products the top line), the reported pose's numpy FK after each move and
reset (the wrist's settle lag makes it a pose of its own), the observation's Euler angles,
the plans and Gymnasium's wrappers.

Renders (same day): a TinyRenderer window costs about 1 ms for the scene's triangles plus
0.25-0.36 us a pixel; with the printed circles drawn at alpha 0 (which TinyRenderer skips:
2.5 us to toggle) a 140 x 140 fragment window took 4.9 ms against 6.3 ms and a 10 x 10
marker window 0.78 ms against 1.09 ms. The fragment and marker masks ignore black, but a
fragment's or the tape's lowest sliver can lie behind a circle printed 0.05 mm above the
paper, so the masks would not be the same bit for bit; not taken. The paper's box drawn as
a mesh without its bottom face was no faster and shaded differently (56,874 pixels of four
frames), so its top face, half of a fragment window's time, is the cost itself.

Compiled float paths (2026-11-25, a later session; quiet machine, load average 1-2): with
the float paths, a step and its reset took 0.82 ms (a loop of 2,000 seeded steps and resets,
and timeit of the parts, one process): the seven touch evaluations 36 us each (inverse
kinematics 11), the moves 130 us each (the cables 20, ``set_joints`` 9 with its motor
command, the plan 8, the end pose's float FK 9, the rest numpy's FK of the start pose and
array handling). numba compiles the Python float paths operation for operation (no
fast-math, so no fused multiply-adds and no reordering; the C library's cos / sin / atan2 /
tanh / sqrt, as Python's math). Two places were not the same at first, found by comparing
27,000 evaluations: ``x ** 2`` (Python calls pow(x, 2.0); LLVM folds a constant exponent
into ``x * x``, which differs from glibc's pow in about one case in a thousand; the
exponent now comes in at run time) and ``math.hypot`` (CPython's own, correctly rounded but
in rare cases; glibc's differs in about one case in 200; the kernel rounds correctly too:
no difference in 6 million pairs). After that, 0 differences, and 9,000 seeded GridTouch
steps and resets gave byte-identical observations, rewards and infos against 5eb2508;
``dvrk-gym reproduce --quick``'s results.json was identical but for wall times. A touch
evaluation then costs 3 us, a move's inverse kinematics 3 us. The step's other costs,
each kept bit for bit: the arm's PyBullet body set once when asked for instead of at every
move and reset (``DvrkWorld.robot`` / ``physics``; the reset's ``restoreState`` leaves the
update pending), a tighter rotation-angle bound (the angle itself below 3 rad) that skips
scipy in a third more plans, np.linalg.norm's own formula without its checks. Left: numpy's
forward kinematics of the reported pose and of each move's start (four a step and reset,
about 17 us each; their bits reach the corrections through OpenBLAS's fused multiply-adds),
the observation's Euler angles, the tool rotation of a new yaw (``pose_from_euler``), the
plans, Gymnasium's wrappers and the action sampling.

CalibrationExploration-v0 (same day, cProfile of 1,500 steps): 60% of a step is TinyRenderer
drawing the marker's two windows (about 1.4 ms each, most of it the scene's triangles). With
the tape and the camera above the printed circles' plane (all but about 3 in 1,000 of the
paper's Phase I poses) the circles are left out of those renders (alpha 0): Phase I's 57
trajectories 23.1 -> 19.1 s, the collected data byte for byte the same.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import pstats
import statistics
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import gymnasium as gym

from dvrk_gym.cli.options import check_flag_bounds

INSTALL = 'pip install -e ".[bench]"  (or: pip install panda-gym==3.0.7)'
REFERENCE = "PandaReach-v3"


@dataclass
class Subject:
    """One env to time: its id, keyword arguments, steps per round, and how to read its simulated time."""

    env_id: str
    kwargs: dict = field(default_factory=dict)
    steps: int = 1000
    label: str = ""
    rates: list[float] = field(default_factory=list)
    cpu_rates: list[float] = field(default_factory=list)
    real_time_factors: list[float] = field(default_factory=list)
    physics_factors: list[float] = field(default_factory=list)


def ratio_text(ratio: float) -> str:
    """A ratio with two decimals, or two significant digits below 0.01 (Debridement's picks
    against PandaReach's steps: 0.0044, not 0.00)."""
    return f"{ratio:.2f}" if ratio >= 0.01 else f"{ratio:.2g}"


def clock_seconds(env: gym.Env) -> float:
    """Seconds on a dvrk_gym env's simulated clock (reset with each episode)."""
    return env.unwrapped.world.clock.time_s


@contextlib.contextmanager
def counting_physics_steps() -> Iterator[list[int]]:
    """Count our envs' ``stepSimulation`` calls (``Physics.step``) while inside; the count is the list's one item."""
    from dvrk_gym.sim.physics.client import Physics

    count = [0]
    step = Physics.step

    def counted(self: Physics, n: int = 1) -> None:
        count[0] += n
        step(self, n)

    Physics.step = counted  # type: ignore[method-assign]
    try:
        yield count
    finally:
        Physics.step = step  # type: ignore[method-assign]


def time_subject(subject: Subject, seed: int) -> None:
    """Make, reset and step ``subject.env_id`` ``subject.steps`` times; append its steps per wall
    and CPU second and its two real-time factors (robot clock, physics integrated)."""
    env = gym.make(subject.env_id, **subject.kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    env.step(env.action_space.sample())  # one-off work (the printed grid's detection) is not a step
    env.reset(seed=seed)
    ours = subject.env_id.startswith("dvrk_gym/")
    simulated = 0.0
    with counting_physics_steps() as physics_steps:
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(subject.steps):
            before = clock_seconds(env) if ours else 0.0
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            simulated += clock_seconds(env) - before if ours else env.unwrapped.sim.dt
            if terminated or truncated:
                env.reset()
        elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        integrated = physics_steps[0] * env.unwrapped.world.physics.time_step_s if ours else simulated
    env.close()
    subject.rates.append(subject.steps / elapsed)
    subject.cpu_rates.append(subject.steps / cpu)
    subject.real_time_factors.append(simulated / elapsed)
    subject.physics_factors.append(integrated / elapsed)


def round_ratios(rates: list[float], reference: list[float]) -> tuple[float, float, float]:
    """Median, least and greatest of the round-by-round ratios ``rates[i] / reference[i]``."""
    ratios = [rate / ref for rate, ref in zip(rates, reference, strict=True)]
    return statistics.median(ratios), min(ratios), max(ratios)


def profile_env(env_id: str, steps: int, picks: int, resolution: tuple[int, int], seed: int) -> int:
    """Print cProfile's view (own time, then cumulative) of ``time_subject`` on one of our envs."""
    import dvrk_gym  # noqa: F401  (registers ours)

    if env_id not in gym.registry or not env_id.startswith("dvrk_gym/"):
        print(f"--profile takes one of our env ids, e.g. dvrk_gym/Debridement-v0; got {env_id!r}", file=sys.stderr)
        return 2
    count = picks if env_id == "dvrk_gym/Debridement-v0" else steps
    subject = Subject(env_id, {"camera_resolution": resolution}, count)
    profiler = cProfile.Profile()
    profiler.runcall(time_subject, subject, seed)
    print(f"{env_id}: {count} steps, {subject.rates[0]:.1f} steps/s under the profiler")
    stats = pstats.Stats(profiler)
    stats.sort_stats("tottime").print_stats(20)
    stats.sort_stats("cumulative").print_stats(40)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="steps per round of each env but Debridement (default: %(default)s)")
    parser.add_argument("--picks", type=int, default=16, help="Debridement-v0 picks per round (default: %(default)s)")
    parser.add_argument(
        "--delta-steps", type=int, default=100, help="Debridement-v0 steps per round in delta mode, 10 Hz (default: %(default)s)"
    )
    parser.add_argument("--rounds", type=int, default=5, help="turns of every env; figures are medians (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seeds every env and its actions (default: %(default)s)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"), help="our endoscope images")
    parser.add_argument("--profile", metavar="ENV_ID", default=None, help="instead: cProfile one of our envs' steps")
    args = parser.parse_args()
    check_flag_bounds(
        parser,
        args,
        {
            "steps": (1, 10**7),
            "picks": (1, 10**5),
            "delta_steps": (1, 10**6),
            "rounds": (1, 1000),
            "seed": (0, 2**31 - 1),
            "resolution": (None, None),
        },
    )
    if args.profile is not None:
        return profile_env(args.profile, args.steps, args.picks, tuple(args.resolution), args.seed)
    try:
        import panda_gym  # noqa: F401  (registers the Panda envs)
    except ImportError:
        print(f"bench_peers needs panda-gym, which is not installed: {INSTALL}", file=sys.stderr)
        return 1
    import dvrk_gym  # noqa: F401  (registers ours)

    resolution = {"camera_resolution": tuple(args.resolution)}
    subjects = [
        Subject("dvrk_gym/GridTouch-v0", resolution, args.steps),
        Subject("dvrk_gym/CalibrationExploration-v0", resolution, args.steps),
        Subject("dvrk_gym/Debridement-v0", resolution, args.picks),
        Subject("dvrk_gym/Debridement-v0", {**resolution, "action_mode": "delta"}, args.delta_steps, "Debridement-v0 (delta)"),
        Subject(REFERENCE, steps=args.steps),
        Subject("PandaPickAndPlace-v3", steps=args.steps),
    ]
    for round_index in range(args.rounds):
        for subject in subjects if round_index % 2 == 0 else subjects[::-1]:
            time_subject(subject, args.seed)
    reference = next(s for s in subjects if s.env_id == REFERENCE)
    header = f"{'x ' + REFERENCE + ' (wall: median, range)':>34} {'x (CPU)':>8} {'clock s/wall s':>15} {'physics s/wall s':>17}"
    print(f"{'env (random actions, resets counted)':<36} {'steps/s':>9} {header}")
    for subject in subjects:
        median, low, high = round_ratios(subject.rates, reference.rates)
        cpu = round_ratios(subject.cpu_rates, reference.cpu_rates)[0]
        wall = f"{ratio_text(median)} ({ratio_text(low)}-{ratio_text(high)})"
        name = subject.label or subject.env_id.removeprefix("dvrk_gym/")
        clock, physics = statistics.median(subject.real_time_factors), statistics.median(subject.physics_factors)
        print(f"{name:<36} {statistics.median(subject.rates):>9.1f} {wall:>34} {ratio_text(cpu):>8} {clock:>15.2f} {physics:>17.2f}")
    print(
        f"medians of {args.rounds} rounds, the ratios round by round (the range: least and greatest); Debridement-v0: one "
        f"step is one pick ({args.picks} a round), in delta mode a 0.1 s motion ({args.delta_steps} a round); resolution "
        f"{resolution}; clock: the robot's time, physics: stepSimulation's"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
