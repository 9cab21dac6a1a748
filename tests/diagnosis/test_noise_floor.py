"""The position fit's noise floor (diagnosis.limbfit, issue 21 item 1): a floor that a
non-linear effect of the perturbation cannot raise, and that a subject's voluntary torque
does not count as gap. Known answers: estimation.synthetic's ankle (the README's example,
a voluntary torque not coherent with the perturbation) and that ankle with a Coulomb
friction added on the limb side of the torque sensor (an analytic non-linear torque);
``noise_floor="white"`` is the floor before (read above the band), shown failing both."""

import json

import numpy as np
import pytest

import trialformat as tf
from diagnosis import limbfit as lf
from estimation.synthetic import position_trial


def _nominal_gap(trial, floor="coherence"):
    cfg = lf.FitConfig(noise_floor=floor)
    g = lf.fit_nominal(lf.prepare([lf.PositionRecord.from_trial(trial)], cfg), cfg)["gaps"]
    return g["all"], cfg


def _friction_trial(seed, share=1.0 / 6.0):
    """The ankle without voluntary torque, plus Fc sign(w) at the footplate (limb side of
    the sensor), Fc = ``share`` of the torque's RMS."""
    tr = position_trial(K=80.0, B=1.2, I=0.012, duration_s=30.0, seed=seed,
                        record_reference=False, voluntary_rms_nm=0.0)
    theta, tau = tr.signal("theta")[:, 0], tr.signal("tau_h")[:, 0]
    friction = share * np.std(tau) * np.sign(np.gradient(theta, 1.0 / tr.fs))
    return tf.Trial(meta=tr.meta, t=tr.t, theta=tr.theta, tau_h=(tau + friction)[:, None],
                    name=f"friction_{seed}")


@pytest.mark.parametrize("seed", [1, 2])
def test_coulomb_friction_at_the_footplate_is_a_significant_gap(seed):
    g, cfg = _nominal_gap(_friction_trial(seed))
    assert g.source == lf.FLOOR_COHERENCE
    assert g.significant(cfg), (g.excess, g.se, g.floor)
    # most of the friction's non-linear residual is gap, not floor
    assert g.excess > 5 * g.floor


def test_the_friction_case_is_no_gap_with_the_floor_read_above_the_band():
    """The failure the coherence floor fixes: sign(w)'s harmonics raise the white level
    in [0.25, 0.45] fs until the floor swallows the gap (seen here through the angle
    noise mapped through the impedance)."""
    trial = _friction_trial(1)
    g_white, cfg = _nominal_gap(trial, "white")
    g_coh, _ = _nominal_gap(trial)
    assert g_white.source == lf.FLOOR_WHITE
    assert g_white.floor > 10 * g_coh.floor or not g_white.significant(cfg) \
        or g_white.excess < 0.5 * g_coh.excess


@pytest.mark.parametrize("reference", [True, False])
def test_the_example_ankle_with_voluntary_torque_has_no_significant_gap(reference):
    """The README's relaxed_1 (seed 101): nothing withheld but the voluntary torque."""
    trial = position_trial(K=80.0, B=1.2, I=0.012, duration_s=60.0, seed=101,
                           torque_sign=-1, record_reference=reference)
    g, cfg = _nominal_gap(trial)
    assert not g.significant(cfg), (g.excess, g.se, g.floor)
    # the voluntary torque is in the floor: it is most of the residual
    assert g.floor > 0.01
    if reference:
        g_white, cfg = _nominal_gap(trial, "white")
        assert g_white.significant(cfg)  # the floor before counted it as gap


def test_white_noise_alone_gives_no_excess_beyond_its_standard_error():
    """The bias correction: the ankle without voluntary torque, 3 seeds, |excess| within
    3 standard errors (the floor's expected value is the noise's)."""
    for seed in (5, 6, 7):
        tr = position_trial(K=80.0, B=1.2, I=0.012, duration_s=30.0, seed=seed,
                            record_reference=False, voluntary_rms_nm=0.0)
        g, cfg = _nominal_gap(tr)
        assert abs(g.excess) < 3 * g.se, (seed, g.excess, g.se)


def test_too_few_segments_fall_back_to_the_white_floor_and_say_so():
    tr = position_trial(K=80.0, B=1.2, I=0.012, duration_s=8.0, seed=3,
                        record_reference=False)
    cfg = lf.FitConfig(welch_s=4.0)
    g = lf.fit_nominal(lf.prepare([lf.PositionRecord.from_trial(tr)], cfg), cfg)["gaps"]
    assert g["all"].source == lf.FLOOR_WHITE


def test_an_unknown_floor_option_is_named():
    tr = position_trial(K=80.0, B=1.2, I=0.012, duration_s=8.0, seed=3)
    cfg = lf.FitConfig(noise_floor="spectral")
    with pytest.raises(ValueError, match="noise_floor.*'spectral'"):
        lf.fit_nominal(lf.prepare([lf.PositionRecord.from_trial(tr)], cfg), cfg)


def test_the_example_ankle_relaxed_1_diagnosis_reports_no_gap_and_its_floor(tmp_path):
    """``armimp diagnose runs/ankle/relaxed_1*``: not "unexplained" any more (issue 21),
    and report.json / report.md say which floor was used."""
    from diagnosis.core import DiagnosisConfig, diagnose
    from estimation.examples import write_ankle
    src = tmp_path / "ankle"
    write_ankle(src)
    one = tmp_path / "one"
    one.mkdir()
    for p in src.glob("relaxed_1.*"):
        (one / p.name).write_bytes(p.read_bytes())
    report = diagnose(one, tmp_path / "out", config=DiagnosisConfig(), progress=False)
    assert report.verdict == "no significant gap", report.summary
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    assert doc["gap"]["noise_floor_source"].startswith("welch non-coherent")
    assert "Noise floor" in (tmp_path / "out" / "report.md").read_text()
