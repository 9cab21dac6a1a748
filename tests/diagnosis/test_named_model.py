"""The named model in full (issue 21, item 6): with an effect named, the report gives the
limb re-fitted with it (K, B, I and the effect, each with its 95 % interval), not only
the nominal limb."""

import json

import numpy as np
import pytest

import trialformat as tf
from diagnosis import diagnose
from diagnosis import limb as lm
from diagnosis.pipeline.report import named_model

K1, B1, I1 = 60.0, 0.8, 0.012
REFLEX = {"gain": 3.0, "delay_s": 0.045, "frequency_hz": 4.0, "rectified": False}


def _reflex_trial(n=30000, fs=1000.0, seed=3):
    """A one-joint limb (known K, B, I) with a stretch reflex under a measured-angle
    drive (diagnosis.limb, the known answer)."""
    from scipy import signal as sps
    rng = np.random.default_rng(seed)
    theta = sps.sosfiltfilt(sps.butter(4, 8.0, fs=fs, output="sos"),
                            rng.standard_normal(n))[:, None]
    theta *= 0.015 / theta.std()
    limb = lm.LimbModel(K=np.array([[K1]]), B=np.array([[B1]]), I=np.array([[I1]]))
    tau = lm.limb_torque(theta, fs, limb, {"stretch_reflex": REFLEX})
    tau = tau + 0.02 * rng.standard_normal(tau.shape)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, perturbation={"kind": "position"},
                sensors={"torque_sampling": "instantaneous"})
    return tf.Trial(meta=meta, t=np.arange(n) / fs, theta=theta, tau_h=tau, name="reflex")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    from diagnosis import DiagnosisConfig
    root = tmp_path_factory.mktemp("named")
    (root / "in").mkdir()
    trial = _reflex_trial()
    tf.write_trial(root / "in" / trial.name, trial)
    return diagnose(root / "in", root / "out", workers=1, progress=False,
                    config=DiagnosisConfig(effects=("stretch_reflex", "stiffness_drift")))


def test_the_report_gives_the_limb_re_fitted_with_the_named_effect(report):
    assert report.named == ["stretch_reflex"], report.summary
    nm = report.named_model
    assert nm["limb_refitted"] is True
    for key, truth, rel in (("K", K1, 0.05), ("B", B1, 0.15), ("I", I1, 0.1)):
        v, lo, hi = nm[key]
        assert lo < v < hi, (key, nm[key])
        assert v == pytest.approx(truth, rel=rel), (key, nm[key])
    # the nominal limb absorbs the reflex's velocity torque in B: the named one does not
    nominal_b = float(np.asarray(report.arm["B_h"]).ravel()[0])
    assert abs(nm["B"][0] - B1) < abs(nominal_b - B1)
    gain, lo, hi = nm["effects"]["stretch_reflex"]["gain"]
    assert lo < gain < hi and gain == pytest.approx(REFLEX["gain"], rel=0.3)
    assert nm["effects"]["stretch_reflex"]["rectified"] is False


def test_report_json_and_md_carry_the_named_model(report):
    data = json.loads((report.out_dir / "report.json").read_text())
    assert data["named_model"]["K"] == pytest.approx(report.named_model["K"])
    text = (report.out_dir / "report.md").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("Named model"))
    assert "the limb re-fitted with the effect" in line
    assert f"K = {report.named_model['K'][0]:.4g} [" in line and "stretch_reflex: gain" in line
    # the intervals include the form (diagnosis.formprofile): which choices were profiled,
    # in named_model and in the effect ranking's row, and a line of report.md
    prof = data["named_model"]["form_profile"]["stretch_reflex"]
    assert prof["profiled"]["damping"] and prof["profiled"]["rectified"] == [False, True]
    assert any(a["kept"] for a in prof["alternatives"])
    row = next(r for r in data["ranking"] if r["effects"] == ["stretch_reflex"])
    assert row["form_profile"]["stretch_reflex"]["best_fitting"] == prof["best_fitting"]
    assert any("intervals include its form" in ln for ln in text.splitlines())


def test_an_exoskeleton_named_model_keeps_the_estimated_arm_and_says_so():
    """The exoskeleton's fits keep the arm estimated from the trials: the named model is
    that arm (its intervals from the estimate's half-widths) and the fitted effect."""
    arm = {"K_h": [[40.0, 0.0], [0.0, 20.0]], "B_h": [[1.0, 0.0], [0.0, 0.5]],
           "M_h": [[0.1, 0.0], [0.0, 0.05]], "method": "full",
           "ci95": {"K_h": [[2.0, 0.0], [0.0, 1.0]], "B_h": [[0.1, 0.0], [0.0, 0.05]],
                    "M_h": [[0.01, 0.0], [0.0, 0.005]]}}
    nm = named_model(arm, {"gravity": {"tilt_deg": 40.0}}, {})
    assert nm["limb_refitted"] is False
    assert nm["K"] == [[40.0, 38.0, 42.0], [20.0, 19.0, 21.0]]
    assert nm["effects"] == {"gravity": {"tilt_deg": [40.0, None, None]}}


def test_the_gap_in_time_gives_the_named_models_gap_beside_the_nominal(report):
    """Issue 20: each time block's feature gap with the named model beside the nominal's;
    the reflex is there all the time, so the named model closes the gap in every block."""
    when = report.gap_in_time
    blocks = [b for b in when["blocks"] if b["gap"] is not None]
    assert blocks and when["named"] == ["stretch_reflex"]
    for b in blocks:
        assert b["gap_named"] is not None and b["gap_named"] < 0.5 * b["gap"], b
    assert when["gap_named_all"] == pytest.approx(report.gap["features"]["named_all"])
    text = (report.out_dir / "report.md").read_text()
    assert "gap with stretch_reflex |" in text
    assert (report.out_dir / "gap_time.png").stat().st_size > 1000
