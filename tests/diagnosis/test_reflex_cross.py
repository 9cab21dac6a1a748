"""The diagnosis against a second implementation: recordings made by the estimator's own
parallel-cascade simulator (estimation.synthetic_reflex: analytic multisine derivatives,
the reflex's activation in continuous time by scipy.signal.lsim, torque noise), which
shares no code with diagnosis.limb, at the magnitudes the measured ankle recordings show
(gain ~30 N m s/rad, activation ~1.7 Hz), in both stretch directions."""

import pytest

import trialformat as tf
from diagnosis import diagnose
from estimation.synthetic_reflex import parallel_cascade_trial


@pytest.mark.parametrize("gain, delay_s, rectify, stretch_sign", [
    (30.0, 0.045, "positive", 1.0),     # stretched by positive velocity, resists it
    (-30.0, 0.030, "negative", -1.0),   # stretched by negative velocity, resists it
])
def test_reflex_of_an_independent_simulator_is_named(tmp_path, gain, delay_s, rectify,
                                                     stretch_sign):
    trial = parallel_cascade_trial(name="ankle", K=80.0, B=1.0, I=0.015, G=gain,
                                   delay_s=delay_s, cutoff_hz=1.7, damping=0.7,
                                   rectify=rectify, duration_s=40.0, noise=0.05, seed=3)
    tf.write_trial(tmp_path / "in" / "ankle", trial)
    report = diagnose(tmp_path / "in", tmp_path / "out", workers=1, progress=False)
    assert report.named == ["stretch_reflex"], report.summary
    fit = report.fitted["stretch_reflex"]
    assert fit["rectified"] is True and fit["stretch_sign"] == stretch_sign
    assert fit["gain"] == pytest.approx(abs(gain), rel=0.05)
    assert fit["delay_s"] == pytest.approx(delay_s, abs=0.002)
    assert fit["frequency_hz"] == pytest.approx(1.7, rel=0.1)
    assert report.gap["named_held_out_reduction"] >= 0.9
