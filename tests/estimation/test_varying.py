"""Parameter-varying K, B, I (estimation.varying, estimation.pvlab): known answers built
analytically (a multisine perturbation on a slow movement, the torque from exact
derivatives), bad scheduling input, and the measured pilot when ../shared holds it."""

import json
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from estimation.varying import VaryingError, VaryingOptions, fit_varying

FS = 1000.0
DUR = 40.0
T = np.arange(int(DUR * FS)) / FS
PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (3, 4)) if p.is_file()), None)


def _signals(K_of, B=0.8, I=0.015, seed=0, noise=0.05):
    """theta = slow sine + multisine 1-30 Hz (exact derivatives); tau = K(rho) dtheta +
    B dtheta' + I dtheta'' + the quasi-static torque of the movement + white noise."""
    rng = np.random.default_rng(seed)
    f = np.arange(1.0, 30.0, 0.25)
    a = 0.02 / np.sqrt(f.size / 2) * np.ones(f.size)
    ph = rng.uniform(0, 2 * np.pi, f.size)
    w = 2 * np.pi * f
    arg = np.outer(T, w) + ph
    d0, d1, d2 = np.sin(arg) @ a, np.cos(arg) @ (a * w), -np.sin(arg) @ (a * w * w)
    rho = -0.1 + 0.3 * np.sin(2 * np.pi * T / 13.0)
    tau = K_of(rho) * d0 + B * d1 + I * d2 + 40 * rho + noise * rng.standard_normal(T.size)
    return rho + d0, tau, rho


def _covered(fit, truth, p="K"):
    return (fit.lo[p] <= truth) & (truth <= fit.hi[p])


def test_stiffness_linear_in_the_angle_is_recovered_within_its_intervals():
    theta, tau, rho = _signals(lambda r: 50 + 100 * r)
    fit = fit_varying(theta, tau, rho, FS, name="sv", units="rad")
    truth = 50 + 100 * fit.rho
    assert _covered(fit, truth).sum() >= 13  # 95 % intervals at 15 points
    # 0.45 N m/rad measured: the movement's leak through the high-pass (varying.HP_ORDER)
    assert np.max(np.abs(fit.values["K"] - truth)) < 0.02 * np.mean(truth)
    assert np.all(_covered(fit, 0.8, "B") | (np.abs(fit.values["B"] / 0.8 - 1) < 0.01))
    assert fit.order >= 1
    h = fit.heldout_vaf_pct
    assert h["varying"] > h["invariant"] + 0.5  # 0.92 measured; flat truth: < 0.1
    assert fit.rho[0] < -0.3 and fit.rho[-1] > 0.1  # rho in its own (absolute) units


def test_constant_truth_gives_a_flat_stiffness():
    # torque noise 0.5 N m, 40 % of the perturbation torque's RMS: at 0.05 the 95 %
    # intervals are +-0.04 N m/rad and a 0.06 % bias (the high-pass) already shows
    theta, tau, rho = _signals(lambda r: 60 + 0 * r, seed=1, noise=0.5)
    fit = fit_varying(theta, tau, rho, FS, name="sv", units="rad")
    # the 15 points lie on one curve: their coverage is not independent (11 measured)
    assert _covered(fit, 60.0).sum() >= 10
    assert np.max(np.abs(fit.values["K"] / 60 - 1)) < 0.01
    half = (fit.hi["K"] - fit.lo["K"]) / 2
    assert np.ptp(fit.values["K"]) < 2 * np.max(half) + 0.02 * 60
    h = fit.heldout_vaf_pct
    assert abs(h["varying"] - h["invariant"]) < 0.1  # no gain from a variation not there


def test_time_as_scheduling_variable():
    K_t = 40 + T  # a stiffness growing 1 N m/rad per second
    theta, tau, rho = _signals(lambda r: 0 * r, seed=2)
    d0 = theta - rho
    tau = tau + K_t * d0
    fit = fit_varying(theta, tau, T, FS, name="time", units="s", is_time=True)
    truth = 40 + fit.rho
    assert _covered(fit, truth).sum() >= 12
    assert np.max(np.abs(fit.values["K"] - truth)) < 0.03 * np.mean(truth)


@pytest.mark.parametrize("case, match", [
    ("length", "values for the recording's"),
    ("nan", "not finite at sample 100"),
    ("constant", "constant"),
])
def test_bad_scheduling_input_is_refused_by_name(case, match):
    theta, tau, rho = _signals(lambda r: 50 + 0 * r)
    if case == "length":
        rho = rho[::2]
    elif case == "nan":
        rho = rho.copy()
        rho[100] = np.nan
    else:
        rho = np.full_like(rho, 0.1)
    with pytest.raises(VaryingError, match=match) as exc:
        fit_varying(theta, tau, rho, FS, name="sv", units="rad")
    assert "'sv'" in str(exc.value)


def test_too_short_a_recording_is_refused_with_what_would_work():
    theta, tau, rho = _signals(lambda r: 50 + 0 * r)
    n = int(8 * FS)
    with pytest.raises(VaryingError, match=r"blocks of 2 s; at least .*\(record"):
        fit_varying(theta[:n], tau[:n], rho[:n], FS, name="sv",
                    options=VaryingOptions())


def _trial(theta, tau, sv, **meta):
    n = theta.size
    m = {"fs": FS, "n_dof": 1, "perturbation": {"kind": "position"}, **meta}
    return tf.Trial(meta=m, t=np.arange(n) / FS, theta=theta.reshape(n, 1),
                    tau_h=tau.reshape(n, 1), extra={"sv": sv}, name="rec")


def test_a_named_variable_of_too_narrow_a_range_keeps_the_time_invariant_answer():
    from estimation.pvlab import varying_of_trials
    from estimation.lab import AnalysisOptions
    theta, tau, rho = _signals(lambda r: 50 + 0 * r)
    narrow = 1e-4 * np.sin(2 * np.pi * T / 13.0) + 0.1 + 1e-3 * np.random.default_rng(
        0).standard_normal(T.size)
    t = _trial(theta, tau, narrow, scheduling="sv")
    fits, notes = varying_of_trials([t], AnalysisOptions())
    assert fits == []
    assert len(notes) == 1 and "'sv'" in notes[0] and "too narrow" in notes[0]
    assert "time-invariant estimate is kept" in notes[0] and "would work" in notes[0]
    # the same variable spreading as the movement does is fitted
    fits, notes = varying_of_trials([_trial(theta, tau, rho, scheduling="sv")],
                                    AnalysisOptions())
    assert len(fits) == 1 and notes == []


def test_a_reversed_torque_sign_is_found_from_the_inertia():
    from estimation.pvlab import sign_warnings, varying_of_trials
    from estimation.lab import AnalysisOptions
    theta, tau, rho = _signals(lambda r: 50 + 100 * r)
    for sign in (1, -1):
        t = _trial(theta, sign * tau, rho, scheduling="sv")
        fits, _ = varying_of_trials([t], AnalysisOptions())
        w = sign_warnings(fits, [t])
        assert (len(w) == 1 and "declare" in w[0]) == (sign == -1)


@pytest.mark.skipif(PILOT is None, reason="../shared/data/reklab-pilot not present")
@pytest.mark.parametrize("declared", [1, -1])
def test_pilot_torque_sign_advice_is_consistent(declared, tmp_path):
    """Declaring either sign gives the same finding: the file's torque is reversed
    (advice only when +1 is declared; with -1 no sign warning, K, I > 0)."""
    from estimation.cli import main
    out = tmp_path / "r.json"
    assert main(["estimate", str(PILOT), "--torque-sign", str(declared),
                 "--json", str(out)]) == 0
    doc = json.loads(out.read_text())[0]
    signs = [w for w in doc["warnings"] if w.startswith("torque sign")]
    pv = doc["parameter_varying"]
    assert pv["scheduling"] == "sv" and pv["units"] == "rad"
    if declared == 1:
        assert len(signs) == 1 and "--torque-sign -1" in signs[0]
    else:
        assert signs == []
        assert all(p["K"][0] > 0 and p["I"][1] > 0 for p in pv["points"])
        assert pv["heldout_vaf_pct"]["varying"] > pv["heldout_vaf_pct"]["invariant"]
        assert pv["points"][-1]["K"][1] > pv["points"][0]["K"][2]  # K rises with the angle
        assert -0.42 < pv["points"][0]["rho"] < pv["points"][-1]["rho"] < 0.21


def test_json_entry_and_figure_files(tmp_path):
    from types import SimpleNamespace
    from estimation.pvlab import varying_json, write_varying_files
    theta, tau, rho = _signals(lambda r: 50 + 100 * r)
    fit = fit_varying(theta, tau, rho, FS, name="sv", units="rad")
    fit.trial = "rec"
    doc = varying_json([fit])
    assert doc["scheduling"] == "sv" and doc["units"] == "rad" and doc["trial"] == "rec"
    assert len(doc["points"]) == 15
    assert set(doc["points"][0]) == {"rho", "K", "B", "I"}
    v, lo, hi = doc["points"][0]["K"]
    assert lo <= v <= hi
    paths = write_varying_files(SimpleNamespace(varying=[fit]), tmp_path, "rec")
    assert [p.name for p in paths] == ["pv_rec.png", "pv_rec.csv"]
    assert all(p.stat().st_size > 0 for p in paths)
    rows = (tmp_path / "pv_rec.csv").read_text().splitlines()
    assert rows[0].startswith("sv [rad],K,K_lo,K_hi") and len(rows) == 16
