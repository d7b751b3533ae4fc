"""How the paper's table sent each calibrator's predictions: the authors' height rules."""

import numpy as np
import pytest

from dvrk_gym import paper
from dvrk_gym.calibration import benchmark
from dvrk_gym.calibration.benchmark import YAW_SETTINGS, calibration_table, paper_table_rules
from dvrk_gym.evaluation.table_protocol import RAW, HeightRule, RuledPolicy, carried_band, paper_rules


def _policy(observation):
    return np.array([0.04, 0.04, observation, 0.3], dtype=np.float32)


def test_a_ruled_policy_clips_then_lifts_and_keeps_both():
    touch = RuledPolicy(_policy, HeightRule(band_m=(-0.18, -0.168), lift_m=0.008))
    assert np.isclose(touch(-0.15)[2], -0.168 + 0.008, atol=1e-7)  # clipped down to the band's top, then lifted
    assert np.isclose(touch(-0.175)[2], -0.175 + 0.008, atol=1e-7)
    assert np.isclose(touch.predicted[0][2], -0.168, atol=1e-7)  # the prediction as the real records keep it: clipped
    assert np.isclose(touch.sent[0][2], -0.16, atol=1e-7) and np.isclose(touch.predicted[1][2], -0.175, atol=1e-7)
    assert np.isclose(RuledPolicy(_policy, HeightRule(None, 0.004))(-0.15)[2], -0.146, atol=1e-7)  # lifted only
    assert RuledPolicy(_policy, RAW)(-0.15)[2] == np.float32(-0.15)


BAD_RULES = [
    ((-0.168, -0.18), 0.0, "lowest < highest"),
    ((-0.18, np.nan), 0.0, "band_m"),
    (-0.18, 0.0, "band_m"),
    ((-0.18, -0.17, -0.16), 0.0, "band_m"),
    ((True, 2.0), 0.0, "band_m"),
    (None, 0.2, "lift_m"),
    (None, np.inf, "lift_m"),
    (None, True, "lift_m"),
    (None, "0.01", "lift_m"),
]


@pytest.mark.parametrize(("band", "lift", "message"), BAD_RULES)
def test_bad_rules_are_refused(band, lift, message):
    with pytest.raises(ValueError, match=message):
        HeightRule(band_m=band, lift_m=lift)


def test_a_rule_keeps_plain_floats_whatever_numbers_it_was_given():
    rule = HeightRule(band_m=[np.float32(-0.18), -0.168], lift_m=np.float64(0.004))
    assert rule.band_m == (float(np.float32(-0.18)), -0.168) and type(rule.lift_m) is float
    assert hash(rule) == hash(HeightRule(band_m=(float(np.float32(-0.18)), -0.168), lift_m=0.004))


def test_the_band_moves_with_where_the_robot_reports_its_pushed_jaws():
    low, high = carried_band(np.full(3, paper.TABLE_PAPER_Z_M + 0.015))
    assert np.isclose(low, paper.TABLE_Z_BAND_M[0] + 0.015) and np.isclose(high, paper.TABLE_Z_BAND_M[1] + 0.015)
    for bad in (np.array([]), np.array([np.nan]), np.zeros((2, 2))):
        with pytest.raises(ValueError, match="pushed_heights_m"):
            carried_band(bad)


def test_the_papers_rules_lift_the_rigid_body_alone_and_clip_where_its_runs_clipped():
    pushed = np.full(4, paper.TABLE_PAPER_Z_M - 0.002)
    rbt = paper_rules("RBT", pushed)
    assert [round(1e3 * rule.lift_m, 6) for rule in rbt] == [8.0, 9.0, 8.0, 6.0, 4.0, 8.0]
    assert [rule.band_m is not None for rule in rbt] == [True, True, False, False, False, True]
    np.testing.assert_allclose(rbt[0].band_m, np.array(paper.TABLE_Z_BAND_M) - 0.002)
    assert paper_rules("DNN", pushed) == paper_rules("DNN+RF", pushed) == (RAW,) * len(YAW_SETTINGS)
    with pytest.raises(ValueError, match="method must be one of"):
        paper_rules("GBR", pushed)
    assert set(paper_table_rules(["RBT", "GBR", "DNN"], pushed)) == {"RBT", "DNN"}  # a calibrator of one's own is sent raw


def test_the_table_sends_each_setting_by_its_own_rule(monkeypatch):
    sent: dict[str, HeightRule | None] = {}

    def fake_pass(env, policy, yaw, seed=0, progress=False):
        label = next(label for label, setting_yaw in YAW_SETTINGS if setting_yaw == yaw)
        sent[label] = policy.rule if isinstance(policy, RuledPolicy) else None
        errors = np.full(35, float(seed))
        return benchmark.CircleErrors(pixel=errors, mm=errors, yaw=np.zeros(35))

    monkeypatch.setattr(benchmark, "touch_grid", fake_pass)
    rules = tuple(HeightRule(band_m=None, lift_m=0.001 * (k + 1)) for k in range(len(YAW_SETTINGS)))
    table = calibration_table(None, {"RBT": _ConstantCalibrator(), "DNN": _ConstantCalibrator()}, seed=50, rules={"RBT": rules})
    assert [sent[label] for label, _ in YAW_SETTINGS] == [None] * 6  # DNN, the last method touched: no rule, sent as it is
    assert [table["RBT"][label].mm[0] for label, _ in YAW_SETTINGS] == [50.0 + k for k in range(6)]  # setting k seeded seed + k
    sent.clear()
    calibration_table(None, {"RBT": _ConstantCalibrator()}, seed=50, rules={"RBT": rules})
    assert [sent[label] for label, _ in YAW_SETTINGS] == list(rules)  # setting k sent by rule k


class _ConstantCalibrator:
    def predict(self, X):
        return np.tile([0.04, 0.04, -0.16], (len(X), 1))


def test_the_table_refuses_rules_it_cannot_apply():
    with pytest.raises(ValueError, match="not among the calibrators"):
        calibration_table(None, {"DNN": object()}, rules={"RBT": (RAW,) * 6})
    with pytest.raises(ValueError, match="one HeightRule per setting"):
        calibration_table(None, {"RBT": object()}, rules={"RBT": (RAW,) * 5})
