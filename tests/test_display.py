"""Tests for the display path: the EGL mirror (dvrk_gym.sim.physics.mirror), the endoscope display
(dvrk_gym.sim.endoscope.display) and the envs' render(); perception stays on TinyRenderer, untouched."""

from __future__ import annotations

import ctypes.util
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import psutil
import pybullet
import pytest
from scipy.spatial.transform import Rotation

from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS, WORKSPACE_CENTER_M, StereoCamera
from dvrk_gym.sim.endoscope.display import EGL_MAX_IMAGE_PX, EndoscopeDisplay, tiles
from dvrk_gym.sim.physics import meshes
from dvrk_gym.sim.physics import mirror as mirror_module
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.physics.egl_probe import egl_plugin_path, egl_usable
from dvrk_gym.sim.physics.mirror import EglMirror, RendererUnavailable, link_frame
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

SMALL = (640, 360)
EGL_REASON = egl_usable(egl_plugin_path() or "")
needs_egl = pytest.mark.skipif(EGL_REASON is not None, reason=f"PyBullet's EGL renderer does not run here: {EGL_REASON}")
CENTROID_TOL_PX = 0.3  # as TinyRenderer's (test_camera); measured max 0.18 px at 320-1024 px wide, |mean| < 0.01 px
CENTROID_BIAS_TOL_PX = 0.05
MEAN_GREY_DIFF_TOL = 10.0  # EGL vs TinyRenderer over a whole Debridement frame: measured 4.3 grey levels
MARKER_OFFSET_TOL_PX = 0.5  # where each renderer draws the red marker, 640 x 360


def red_centroid(image: np.ndarray) -> np.ndarray:
    """Centroid (u, v) in px of the red pixels of an RGB image."""
    r, g, b = (image[:, :, i].astype(int) for i in range(3))
    moments = cv2.moments(((r > 100) & (g < 80) & (b < 80)).astype(np.uint8), binaryImage=True)
    assert moments["m00"] > 0, "no red pixels found"
    return np.array([moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]])


@pytest.fixture
def world():
    built = DvrkWorld(WorldConfig(camera_resolution=SMALL))
    yield built
    built.close()


def _sphere_scene() -> tuple[Physics, int]:
    """A white slab and a red sphere of radius 1.5 mm, registered in a Physics."""
    physics = Physics()
    c = physics.client
    centre = np.asarray(WORKSPACE_CENTER_M)
    slab = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=[0.0375, 0.0375, 0.005], rgbaColor=[1, 1, 1, 1])
    physics.add("slab", c.createMultiBody(0, baseVisualShapeIndex=slab, basePosition=(centre - [0, 0, 0.005]).tolist()))
    red = c.createVisualShape(pybullet.GEOM_SPHERE, radius=0.0015, rgbaColor=[1, 0, 0, 1])
    return physics, physics.add("sphere", c.createMultiBody(0, baseVisualShapeIndex=red, basePosition=centre.tolist()))


def test_egl_runs_wherever_libegl_is_installed():
    """Where the system has libEGL (CI installs it), the EGL tests below must run, not skip."""
    if ctypes.util.find_library("EGL") is None:
        pytest.skip("this machine has no libEGL: the fallback tests cover it")
    assert EGL_REASON is None, EGL_REASON


# ---------------------------------------------------------------------------------------------- geometry
def test_tiles_cover_the_image_once_and_fit_the_egl_surface():
    for width, height in [(1920, 1080), (640, 360), (1024, 768), (1025, 769), (3840, 2160), (16, 16)]:
        cover = np.zeros((height, width), dtype=int)
        for tile in tiles(width, height, EGL_MAX_IMAGE_PX):
            assert 0 < tile.width <= EGL_MAX_IMAGE_PX[0] and 0 < tile.height <= EGL_MAX_IMAGE_PX[1]
            cover[tile.v0 : tile.v0 + tile.height, tile.u0 : tile.u0 + tile.width] += 1
        assert np.all(cover == 1), (width, height)
    assert len(tiles(1920, 1080, EGL_MAX_IMAGE_PX)) == 4


def _points_in_view(camera: StereoCamera, rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """``count`` random points over the paper (base frame, m) that both cameras see, 10% in from every edge."""
    k = camera.intrinsics
    points: list[np.ndarray] = []
    while len(points) < count:
        point = np.asarray(WORKSPACE_CENTER_M) + rng.uniform([-0.03, -0.03, 0.002], [0.03, 0.03, 0.02])
        uv = np.array([camera.project(point)[side][0] for side in range(2)])
        if np.all((uv >= [0.1 * k.width, 0.1 * k.height]) & (uv <= [0.9 * k.width, 0.9 * k.height])):
            points.append(point)
    return points


@needs_egl
@pytest.mark.parametrize("resolution", [(320, 180), (1024, 576), (1920, 1080)])
def test_egl_pixels_agree_with_the_camera_projection(resolution):
    """Red sphere centroids in EGL frames (tiled at 1920 x 1080) lie where StereoCamera.project puts them."""
    physics, sphere = _sphere_scene()
    display = EndoscopeDisplay(StereoCamera(PAPER_INTRINSICS.scaled(*resolution)), renderer="egl")
    rng = np.random.default_rng(0)
    errors = []
    try:
        for point in _points_in_view(display.camera, rng, count=6):
            physics.client.resetBasePositionAndOrientation(sphere, point.tolist(), [0, 0, 0, 1])
            for index, side in enumerate(("left", "right")):
                image = display.image(physics, side)
                assert image.shape == (resolution[1], resolution[0], 3) and image.dtype == np.uint8
                errors.append(red_centroid(image) - display.camera.project(point)[index][0])
    finally:
        display.close()
        physics.close()
    errors = np.array(errors)
    assert np.abs(errors).max() < CENTROID_TOL_PX, errors
    assert np.abs(errors.mean(axis=0)).max() < CENTROID_BIAS_TOL_PX, errors.mean(axis=0)


@needs_egl
def test_egl_refuses_images_larger_than_its_surface(world):
    mirror = EglMirror()
    try:
        mirror.sync(world.physics)
        with pytest.raises(ValueError, match="tiles"):
            mirror.image(1920, 1080, world.camera.view_matrix("left"), world.camera.projection_matrix(renderer="opengl"))
    finally:
        mirror.close()


# ---------------------------------------------------------------------------------------------- the mirror
@needs_egl
def test_mirror_holds_every_visual_shape_at_its_world_pose():
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=SMALL, render_mode="rgb_array")
    try:
        env.reset(seed=3)
        env.step(env.action_space.sample())  # the arm somewhere, fragments settled
        physics = env.unwrapped.world.physics
        mirror = EglMirror()
        try:
            mirror.sync(physics)
            expected = sorted(
                (physics.body(name), entry[1])
                for name in physics.body_names
                for entry in physics.client.getVisualShapeData(physics.body(name))
            )
            assert sorted((body, link) for body, link, _ in mirror.copies) == expected
            for body, link, mirror_body in mirror.copies:
                position, orientation = mirror.client.getBasePositionAndOrientation(mirror_body)
                want_position, want_orientation = link_frame(physics.client, body, link)
                np.testing.assert_allclose(position, want_position, atol=1e-9)
                angle = (Rotation.from_quat(orientation).inv() * Rotation.from_quat(want_orientation)).magnitude()
                assert angle < 1e-9
        finally:
            mirror.close()
    finally:
        env.close()


@needs_egl
def test_mirror_follows_bodies_that_come_and_go(world):
    mirror = EglMirror()
    try:
        mirror.sync(world.physics)
        before = len(mirror.copies)
        c = world.physics.client
        ball = c.createVisualShape(pybullet.GEOM_SPHERE, radius=0.002, rgbaColor=[0, 1, 0, 1])
        world.physics.add("ball", c.createMultiBody(0, baseVisualShapeIndex=ball, basePosition=list(WORKSPACE_CENTER_M)))
        mirror.sync(world.physics)
        assert len(mirror.copies) == before + 1
        world.physics.remove("ball")
        mirror.sync(world.physics)
        assert len(mirror.copies) == before
    finally:
        mirror.close()


@needs_egl
def test_mirror_refuses_a_mesh_it_was_not_told_of(world):
    c = world.physics.client
    hidden = meshes.discs(np.array([WORKSPACE_CENTER_M]), 0.002).visual_shape(c, (0, 0, 1, 1))  # not through Physics.mesh_visual
    world.physics.add("hidden", c.createMultiBody(0.0, -1, hidden))
    mirror = EglMirror()
    try:
        with pytest.raises(RendererUnavailable, match="hidden"):
            mirror.sync(world.physics)
    finally:
        mirror.close()


@needs_egl
def test_egl_frame_shows_the_scene_tinyrenderer_shows():
    """Same objects in the same places: the marker within half a pixel, the frames a few grey levels apart."""
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=SMALL, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        world = env.unwrapped.world  # the tool waits beside the receptacle, its marker in view
        egl = env.render()
        tiny = world.render("left")
        assert env.unwrapped._display.renderer == "egl"
        assert np.abs(egl.astype(int) - tiny.astype(int)).mean() < MEAN_GREY_DIFF_TOL
        assert np.linalg.norm(red_centroid(egl) - red_centroid(tiny)) < MARKER_OFFSET_TOL_PX
    finally:
        env.close()


@needs_egl
def test_egl_frames_repeat_bit_for_bit_for_the_same_seed_and_actions():
    frames = []
    for _ in range(2):
        env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=SMALL, render_mode="rgb_array")
        try:
            env.reset(seed=5)
            env.step(np.array([0.03, 0.04, -0.158, 0.0], dtype=np.float32))
            frames += [env.render(), env.render()]
            assert env.unwrapped._display.renderer == "egl"
        finally:
            env.close()
    assert all(np.array_equal(frames[0], frame) for frame in frames[1:])


# ---------------------------------------------------------------------------------------------- perception
@needs_egl
def test_perception_is_bit_identical_with_an_egl_display_at_work():
    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=SMALL, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        world = env.unwrapped.world
        before = [world.render(side) for side in ("left", "right")]
        marker_before = world.observe_marker()
        for _ in range(2):
            env.render()
        assert env.unwrapped._display.renderer == "egl"
        after = [world.render(side) for side in ("left", "right")]
        marker_after = world.observe_marker()
    finally:
        env.close()
    for old, new in zip(before, after):
        assert np.array_equal(old, new)
    assert np.array_equal(marker_before.left_uv, marker_after.left_uv, equal_nan=True)
    assert np.array_equal(marker_before.right_uv, marker_after.right_uv, equal_nan=True)


def test_tiny_renderer_display_gives_the_perception_pixels(world):
    display = EndoscopeDisplay(world.camera, renderer="tiny")
    assert display.renderer == "tiny"
    assert np.array_equal(display.image(world.physics, "left"), world.render("left"))
    assert np.array_equal(display.image(world.physics, "right"), world.render("right"))


# ---------------------------------------------------------------------------------------------- fallback
def test_auto_falls_back_to_tinyrenderer_with_one_log_line_when_egl_cannot_start(world, tmp_path, caplog):
    not_a_plugin = tmp_path / "eglRenderer.so"
    not_a_plugin.write_bytes(b"not a shared library")
    display = EndoscopeDisplay(world.camera, renderer="auto", plugin_path=str(not_a_plugin))
    with caplog.at_level(logging.WARNING, logger="dvrk_gym.sim.endoscope.display"):
        image = display.image(world.physics, "left")
        display.image(world.physics, "left")
    assert display.renderer == "tiny"
    assert np.array_equal(image, world.render("left"))
    said = [record for record in caplog.records if record.name == "dvrk_gym.sim.endoscope.display"]
    assert len(said) == 1 and "TinyRenderer" in said[0].getMessage() and "\n" not in said[0].getMessage()
    insisting = EndoscopeDisplay(world.camera, renderer="egl", plugin_path=str(not_a_plugin))
    with pytest.raises(RendererUnavailable, match="renderer='egl'"):
        insisting.image(world.physics, "left")


FORKED_AFTER_EGL = """
import multiprocessing, os, gymnasium as gym, dvrk_gym
from dvrk_gym.sim.physics.mirror import RendererUnavailable
kwargs = dict(camera_resolution=(320, 180), render_mode="rgb_array", render_resolution=(160, 96))
parent = gym.make("dvrk_gym/GridTouch-v0", **kwargs); parent.reset(seed=0); parent.render()
def child(renderer):
    env = gym.make("dvrk_gym/GridTouch-v0", renderer=renderer, **kwargs); env.reset(seed=0)
    try:
        frame = env.render()
        print("CHILD", renderer, frame.shape, env.unwrapped._display.renderer, flush=True)
    except RendererUnavailable as error:
        print("CHILD", renderer, "refused:", "forked" in str(error) and "spawn" in str(error), flush=True)
    os._exit(0)
def inherited():  # the parent's env, drawing with EGL since before the fork
    frame = parent.render()
    print("INHERITED", frame.shape, parent.unwrapped._display.renderer, flush=True)
    parent.close()  # must leave the parent's client and mesh files alone
    os._exit(0)
for target, args in ((child, ("auto",)), (child, ("egl",)), (inherited, ())):
    process = multiprocessing.get_context("fork").Process(target=target, args=args)
    process.start(); process.join(90)
    if process.is_alive():
        process.kill(); print("CHILD", target.__name__, args, "hung", flush=True)
parent.reset(seed=1)
print("PARENT", parent.render().shape, parent.unwrapped._display.renderer, flush=True)
"""


@needs_egl
def test_a_process_forked_after_egl_drew_renders_with_tinyrenderer_instead_of_hanging():
    """An async vector env forks its workers: a worker reusing the parent's EGL client crashed,
    and one starting its own hung in its first frame. Such a process draws with TinyRenderer
    ("auto") or is refused in one line ("egl"); the parent still draws with EGL."""
    done = subprocess.run(
        [sys.executable, "-c", FORKED_AFTER_EGL],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    said = [line for line in done.stdout.splitlines() if line.startswith(("CHILD", "INHERITED", "PARENT"))]
    expected = ["CHILD auto (96, 160, 3) tiny", "CHILD egl refused: True", "INHERITED (96, 160, 3) tiny", "PARENT (96, 160, 3) egl"]
    assert said == expected, done.stdout


@pytest.mark.slow
@pytest.mark.skipif(not (shutil.which("unshare") and hasattr(os, "geteuid") and os.geteuid() == 0), reason="needs root and unshare")
def test_without_libegl_render_falls_back_to_tinyrenderer_in_the_same_process():
    """libEGL hidden (bind-mounted over by /dev/null in a private mount namespace): the plugin
    would exit() the process; the probe sees it, and render() works on TinyRenderer."""
    libraries = [
        Path(p).resolve() for p in ("/lib/x86_64-linux-gnu/libEGL.so.1", "/usr/lib/x86_64-linux-gnu/libEGL.so.1") if Path(p).exists()
    ]
    if not libraries:
        pytest.skip("no libEGL.so.1 to hide")
    hide = "; ".join(f"mount --bind /dev/null {path}" for path in sorted(set(libraries)))
    code = (
        "import logging, gymnasium as gym, dvrk_gym; logging.basicConfig(level=logging.WARNING);"
        "env = gym.make('dvrk_gym/GridTouch-v0', camera_resolution=(256, 144), render_mode='rgb_array'); env.reset(seed=0);"
        "frame = env.render(); print('RENDERED', frame.shape, env.unwrapped._display.renderer); env.close()"
    )
    done = subprocess.run(
        ["unshare", "-m", "sh", "-c", f'{hide}; exec "$0" -c "$1"', sys.executable, code],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
    )
    if done.returncode != 0 and "mount" in done.stderr and "RENDERED" not in done.stdout:
        pytest.skip(f"could not hide libEGL here: {done.stderr.strip()[-200:]}")
    assert done.returncode == 0, done.stderr
    assert "RENDERED (144, 256, 3) tiny" in done.stdout
    fallback_lines = [line for line in done.stderr.splitlines() if "TinyRenderer" in line]
    assert len(fallback_lines) == 1, done.stderr


# ---------------------------------------------------------------------------------------------- envs
@pytest.mark.parametrize("renderer", ["auto", "tiny"])
def test_render_resolution_sets_the_frame_size_and_leaves_detections_at_the_camera_resolution(make_env, renderer):
    env = make_env("dvrk_gym/GridTouch-v0", render_mode="rgb_array", render_resolution=(320, 180), renderer=renderer)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (180, 320, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # a picture, not a blank
    assert env.unwrapped.world.render("left").shape == (SMALL[1], SMALL[0], 3)


def test_render_settings_are_checked(make_env):
    with pytest.raises(ValueError, match="renderer"):
        make_env("dvrk_gym/GridTouch-v0", renderer="opengl")
    with pytest.raises(ValueError, match="render_resolution"):
        make_env("dvrk_gym/GridTouch-v0", render_resolution=(0, 10))
    with pytest.raises(ValueError, match="render_resolution"):
        make_env("dvrk_gym/GridTouch-v0", render_resolution="640x360")


@needs_egl
def test_closing_an_env_frees_its_mirror_client_files_and_processes(tmp_path):
    before_children = {child.pid for child in psutil.Process().children(recursive=True)}
    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=(256, 144), render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    mirror = env.unwrapped._display._mirror
    client_id = mirror.client._client
    folder = Path(mirror_module._mesh_folder())  # the process's, kept until it exits: names repeat
    assert folder.is_dir() and pybullet.getConnectionInfo(physicsClientId=client_id)["isConnected"]
    env.close()
    assert list(folder.iterdir()) == []  # each rebuild deletes its mesh files once read
    assert not pybullet.getConnectionInfo(physicsClientId=client_id)["isConnected"]
    assert {child.pid for child in psutil.Process().children(recursive=True)} <= before_children


_NAMES_SCRIPT = """
import gymnasium as gym, dvrk_gym
from dvrk_gym.sim.physics import mirror
written = []
mirror.atomic_write_text = lambda path, text, _write=mirror.atomic_write_text: (written.append(path), _write(path, text))[1]
for seed in range(3):  # three envs, one after another, each with its own mirror
    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=(256, 144), render_mode="rgb_array")
    env.reset(seed=seed)
    env.render()
    env.close()
    print(len(written), len(set(written)), flush=True)
print(mirror._mesh_folder())
"""


@needs_egl
def test_mirrors_of_envs_made_one_after_another_reuse_their_mesh_file_names():
    """PyBullet keeps every mesh file name it is given: each mirror's own folder of meshes cost
    0.14 MB for each env that rendered, for good (a sweep of thousands of envs, hundreds of MB). The
    process's one folder is deleted when it exits."""
    done = subprocess.run([sys.executable, "-c", _NAMES_SCRIPT], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    *counts, folder = done.stdout.split("\n")[:-1]
    (first, distinct), *later = (tuple(map(int, line.split())) for line in counts)
    assert first == distinct > 0 and later == [(2 * first, first), (3 * first, first)]  # the same names again
    assert not Path(folder).exists()
    assert "Exception ignored" not in done.stderr  # a closed env collected at exit frees nothing again


_MEMORY_SCRIPT = """
import gc, psutil, gymnasium as gym, dvrk_gym
process = psutil.Process()
env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=(320, 180), render_mode="rgb_array")
for seed in range(15):  # warm up: allocator pools, the renderer's buffers
    env.reset(seed=seed)
    env.render()
gc.collect()
start = process.memory_info().rss
for seed in range(60):  # each reset rebuilds the world, and so the mirror
    env.reset(seed=seed)
    env.render()
gc.collect()
print((process.memory_info().rss - start) / 1e6)
env.close()
"""


@pytest.mark.slow
@needs_egl
def test_memory_stays_flat_over_repeated_renders_and_resets():
    """In a process of its own: a test worker's resident size also moves with what the tests
    before it left in its allocator (6.2 MB once in CI, 0.1-0.3 MB in a fresh process)."""
    result = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT], capture_output=True, text=True, timeout=600, check=True)
    grown_mb = float(result.stdout.strip().splitlines()[-1])
    assert grown_mb < 5.0, f"{grown_mb:.1f} MB over 60 resets with a frame each (0.6 MB a reset before the fixes)"


_TWO_DISPLAYS = """
import gymnasium as gym, numpy as np, dvrk_gym
make = lambda: gym.make("dvrk_gym/Debridement-v0", camera_resolution=(320, 180), render_mode="rgb_array", renderer="egl")
first = make()
first.reset(seed=0)
alone = first.render()
second = make()
second.reset(seed=1)  # other fragments: a copy of another world, built in the same process
other = second.render()
assert not np.array_equal(other, alone)
assert np.array_equal(first.render(), alone), "the first display changed when a second one drew"
second.close()
assert np.array_equal(first.render(), alone), "the first display changed when the second closed"
del second
third = make()
third.reset(seed=1)
assert np.array_equal(third.render(), other)
first.close()
third.close()
print("displays ok")
"""


@needs_egl
def test_displays_of_two_envs_draw_alike_and_closing_one_leaves_the_other_drawing():
    """The EGL plugin's state is the process's: closing one env's display crashed the next frame of
    another (exit 139), and one display's rebuild blanked the other's frames."""
    done = subprocess.run([sys.executable, "-c", _TWO_DISPLAYS], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0 and "displays ok" in done.stdout, (done.returncode, done.stderr[-2000:])


_DISPLAY_IN_A_THREAD = """
import threading, gymnasium as gym, numpy as np, dvrk_gym
make = lambda: gym.make("dvrk_gym/Debridement-v0", camera_resolution=(320, 180), render_mode="rgb_array", renderer="egl")
first = make()
first.reset(seed=1)
alone = first.render()
drawn = {}
def draw_in_a_thread():
    env = make()
    env.reset(seed=1)
    drawn["frame"] = env.render()
    env.close()
thread = threading.Thread(target=draw_in_a_thread)
thread.start()
thread.join()
assert np.array_equal(drawn["frame"], alone) and np.array_equal(first.render(), alone)
first.close()
print("threads ok")
"""


@needs_egl
def test_an_env_drawn_in_another_thread_draws_as_one_in_the_main_thread():
    """The EGL context is the loading thread's: sharing one client across threads crashed (exit 139)."""
    done = subprocess.run([sys.executable, "-c", _DISPLAY_IN_A_THREAD], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0 and "threads ok" in done.stdout, (done.returncode, done.stderr[-2000:])
