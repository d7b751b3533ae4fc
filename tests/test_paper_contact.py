"""The paper's give and slide under the jaws: the model, and its identification from the authors' records."""

import dataclasses

import numpy as np
import pytest
from benchmark_scripts import run_script, script_path

from dvrk_gym.calibration.datasets import load_paper_table_runs
from dvrk_gym.fidelity.contact import depth_under_pushes, fit_contact, height_over_pushes, pushes_of_run
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.identified import PAPER_CONTACT
from dvrk_gym.sim.table.contact import COMPLIANT, RIGID, PaperContact


def test_the_command_goes_on_down_short_of_its_target_by_the_give():
    contact = PaperContact(slide_per_depth=(0.5, -0.25), give=0.4)
    assert contact.command_height(-0.160, -0.150) == -0.150  # the target is over first contact: reached
    assert contact.command_height(-0.160, -0.170) == pytest.approx(-0.170 + 0.4 * 0.010)  # m
    assert RIGID.command_height(-0.160, -0.170) == -0.160  # stops at first contact, exactly
    tip = np.array([0.01, 0.02, -0.1641])
    np.testing.assert_allclose(contact.touch_point(tip, 0.010, -0.164), [0.015, 0.0175, -0.164])  # slid, held on the paper
    assert contact.touch_point(tip, 0.0, -0.164) is tip and RIGID.touch_point(tip, 0.010, -0.164) is tip
    assert COMPLIANT.slide_per_depth == PAPER_CONTACT.slide_per_depth and COMPLIANT.give == PAPER_CONTACT.give


def test_the_slide_grows_with_the_depth_and_is_none_over_the_paper():
    contact = PaperContact(slide_per_depth=(0.5, -0.25), give=0.4)
    np.testing.assert_allclose(contact.slide_m(0.004), [0.002, -0.001])  # m
    assert np.array_equal(contact.slide_m(0.0), [0.0, 0.0]) and np.array_equal(contact.slide_m(-0.003), [0.0, 0.0])
    assert contact.slides and COMPLIANT.slides and not RIGID.slides
    assert not PaperContact(slide_per_depth=(0.0, 0.0), give=0.4).slides  # gives, but does not slide


BAD_CONTACTS = [
    ((0.1,), 0.5, "slide_per_depth"),
    (0.1, 0.5, "slide_per_depth"),
    ("ab", 0.5, "slide_per_depth"),
    ((0.1, np.nan), 0.5, "slide_per_depth"),
    ((9.0, 0.0), 0.5, "slide_per_depth"),
    ((True, 0.0), 0.5, "slide_per_depth"),
    ((0.0, 0.0), 1.5, "give"),
    ((0.0, 0.0), True, "give"),
]


@pytest.mark.parametrize(("slide", "give", "message"), BAD_CONTACTS)
def test_bad_contacts_are_refused(slide, give, message):
    with pytest.raises(ValueError, match=message):
        PaperContact(slide_per_depth=slide, give=give)


def test_a_contact_keeps_plain_floats_whatever_numbers_it_was_given():
    contact = PaperContact(slide_per_depth=[np.float32(0.0), 0], give=np.float64(1.0))
    assert contact.slide_per_depth == (0.0, 0.0) and type(contact.give) is float
    assert contact == RIGID  # so the rigid paper's shortcut holds for it too
    tip = np.array([0.01, 0.02, -0.1641])
    assert contact.touch_point(tip, 0.010, -0.164) is tip


def test_heights_are_measured_over_the_plane_of_the_pushes():
    pushed = np.array([[0.0, 0.0, -0.1], [0.01, 0.0, -0.101], [0.0, 0.01, -0.1], [0.01, 0.01, -0.101]])
    points = np.array([[0.005, 0.005, -0.1], [0.02, 0.0, -0.105]])
    np.testing.assert_allclose(height_over_pushes(points, pushed), [0.0005, -0.003], atol=1e-12)
    np.testing.assert_allclose(depth_under_pushes(points, pushed), [0.0, 0.003], atol=1e-12)


def test_the_identified_contact_is_the_fit_to_the_rigid_bodys_runs():
    """Identified, not tuned: the simulator's values are this fit, rounded as printed."""
    fit = fit_contact(load_paper_table_runs(), ("RBT",))
    np.testing.assert_allclose(fit.slide_per_depth, PAPER_CONTACT.slide_per_depth, atol=5e-4)
    assert fit.give == pytest.approx(PAPER_CONTACT.give, abs=5e-4)
    assert (fit.touches, fit.touches_under) == (175, 93)
    assert (np.abs(fit.slide_per_depth) > 4 * fit.slide_se).all() and fit.give > 20 * fit.give_se  # well away from none


def test_the_fit_gives_back_a_known_give_and_slide():
    """Records rewritten by a known contact (the real sent heights and pushes) are fitted back."""
    runs = load_paper_table_runs()
    camera, slide, give = StereoCamera(), np.array([0.3, -0.6]), 0.25
    rng = np.random.default_rng(0)
    end_effector, reported = runs.end_effector_px.copy(), runs.reported.copy()
    for method in ("DNN", "DNN+RF"):
        for setting in range(5):
            mine = np.flatnonzero((runs.method == method) & (runs.setting == setting))
            depth = depth_under_pushes(runs.sent[mine], pushes_of_run(runs, method, setting))
            run_offset = rng.normal(0.0, 10.0, 2)  # px: the run's own miss
            for i, d in zip(mine, depth, strict=True):
                point = runs.sent[i]
                uv, _ = camera.project(np.array([point, point + np.r_[slide * d, 0.0]]))
                end_effector[i] = runs.circle_px[i] + run_offset + (uv[1] - uv[0]) + rng.normal(0.0, 0.5, 2)
                reported[i, 2] = runs.sent[i, 2] + 2e-4 + give * d + rng.normal(0.0, 2e-5)
    rewritten = dataclasses.replace(runs, end_effector_px=end_effector, reported=reported)
    fit = fit_contact(rewritten, ("DNN", "DNN+RF"), camera)
    np.testing.assert_allclose(fit.slide_per_depth, slide, atol=0.02)
    assert fit.give == pytest.approx(give, abs=0.005)


def test_the_fit_refuses_unknown_methods_and_runs_that_never_went_under():
    runs = load_paper_table_runs()
    with pytest.raises(ValueError, match="methods must be some of"):
        fit_contact(runs, ("SAC",))
    with pytest.raises(ValueError, match="methods must be some of"):
        fit_contact(runs, ())
    lifted = dataclasses.replace(runs, sent=runs.sent + [0.0, 0.0, 0.05])
    with pytest.raises(ValueError, match="no touch of"):
        fit_contact(lifted, ("RBT",))
    with pytest.raises(ValueError, match="fixed yaw"):
        pushes_of_run(runs, "RBT", 5)
    with pytest.raises(ValueError, match="method must be one of"):
        pushes_of_run(runs, "SAC", 0)
    with pytest.raises(ValueError, match="at least three pushed positions"):
        height_over_pushes(np.zeros((2, 3)), np.zeros((2, 3)))


def test_the_identification_script_prints_the_fit_and_its_check():
    run = run_script(script_path("identify_contact"))
    assert run.returncode == 0, run.stderr
    out = run.stdout
    fitted = next(line for line in out.splitlines() if line.strip().startswith("fit: RBT"))
    assert "slide x -0.710 (0.042)  y +0.232 (0.042)" in fitted and "give 0.390 (0.008)" in fitted
    assert sum(line.strip().startswith("held out:") for line in out.splitlines()) == 3
    control = [line for line in out.splitlines() if line.strip().startswith("RBT ") and "image u" in line]
    assert len(control) == 1 and "reported minus sent -0.006 mm/mm" in control[0]  # over the paper: nothing gives
    assert out.splitlines()[-1].endswith("this fit rounds to (-0.710, 0.232), 0.390")
