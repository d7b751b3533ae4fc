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


def _rewritten(methods, slide, give, dead_zone_m=0.0, noise_px=0.5):
    """The records with the image offsets and reported heights of ``methods``' touches made
    again by a known contact (the real sent heights and pushes), and the camera used."""
    runs = load_paper_table_runs()
    camera = StereoCamera()
    rng = np.random.default_rng(0)
    end_effector, reported = runs.end_effector_px.copy(), runs.reported.copy()
    for method in methods:
        for setting in range(5):
            mine = np.flatnonzero((runs.method == method) & (runs.setting == setting))
            depth = np.maximum(depth_under_pushes(runs.sent[mine], pushes_of_run(runs, method, setting)) - dead_zone_m, 0.0)
            run_offset = rng.normal(0.0, 10.0, 2)  # px: the run's own miss
            for i, d in zip(mine, depth, strict=True):
                point = runs.sent[i]
                uv, _ = camera.project(np.array([point, point + np.r_[slide * d, 0.0]]))
                end_effector[i] = runs.circle_px[i] + run_offset + (uv[1] - uv[0]) + rng.normal(0.0, noise_px, 2)
                reported[i, 2] = runs.sent[i, 2] + 2e-4 + give * d + rng.normal(0.0, 2e-5)
    return dataclasses.replace(runs, end_effector_px=end_effector, reported=reported), camera


def test_the_fit_gives_back_a_known_give_and_slide():
    """Records rewritten by a known contact (the real sent heights and pushes) are fitted back."""
    slide, give = np.array([0.3, -0.6]), 0.25
    rewritten, camera = _rewritten(("DNN", "DNN+RF"), slide, give)
    fit = fit_contact(rewritten, ("DNN", "DNN+RF"), camera)
    np.testing.assert_allclose(fit.slide_per_depth, slide, atol=0.02)
    assert fit.give == pytest.approx(give, abs=0.005)
    assert fit.dead_zone_m == 0.0 and fit.slide_rms_px == pytest.approx(0.5, rel=0.2)  # px: the noise put in


def test_a_dead_zone_is_fitted_back_and_fits_best_where_it_is():
    slide, give = np.array([-0.8, 0.25]), 0.45
    rewritten, camera = _rewritten(("RBT",), slide, give, dead_zone_m=0.0015)
    fits = {d: fit_contact(rewritten, ("RBT",), camera, dead_zone_m=1e-3 * d) for d in (0.0, 1.5, 3.0)}
    np.testing.assert_allclose(fits[1.5].slide_per_depth, slide, atol=0.02)
    assert fits[1.5].give == pytest.approx(give, abs=0.005) and fits[1.5].dead_zone_m == 0.0015
    assert fits[1.5].slide_rms_px < min(fits[0.0].slide_rms_px, fits[3.0].slide_rms_px)
    assert fits[1.5].give_rms_m < min(fits[0.0].give_rms_m, fits[3.0].give_rms_m)
    assert fits[3.0].touches_under < fits[1.5].touches_under < fits[0.0].touches_under == 93
    for bad in (-1e-3, 0.02, float("nan"), True):
        with pytest.raises(ValueError, match="dead_zone_m"):
            fit_contact(rewritten, ("RBT",), camera, dead_zone_m=bad)
    with pytest.raises(ValueError, match="beyond 10 mm under the paper"):
        fit_contact(rewritten, ("DNN",), camera, dead_zone_m=0.01)


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
    assert any(line.endswith("this fit rounds to (-0.710, 0.232), 0.390") for line in out.splitlines())
    hinges = [line for line in out.splitlines() if line.strip().startswith("dead zone")]
    assert len(hinges) == 8 and hinges[0].endswith("F +0.0") and "slide 0.75 mm per mm" in hinges[0]
    f_by_zone = {float(line.split()[2]): float(line.split("F ")[-1]) for line in hinges}
    assert max(f_by_zone, key=f_by_zone.get) in (0.75, 1.0) and max(f_by_zone.values()) > 10  # the records' hinge
