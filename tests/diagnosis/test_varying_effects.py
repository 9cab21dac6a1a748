"""Time- and state-varying catalogue effects (diagnosis.varying_effects): known-answer
recordings simulated here from the analytic torque K(t) theta + B omega + I alpha, the
held-out split each effect uses, and the nesting rule."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from diagnosis import limbfit as lf
from diagnosis import varying_effects as vary

FS, DUR = 400.0, 36.0
K0, B0, I0 = 40.0, 0.8, 0.01


def _record(k_factor, theta_slow=None, seed=0):
    rng = np.random.default_rng(seed)
    n = int(FS * DUR)
    t = np.arange(n) / FS
    b, a = signal.butter(2, 8.0, fs=FS)
    pert = signal.lfilter(b, a, rng.standard_normal(n)) * 0.02
    theta = pert + (0 if theta_slow is None else theta_slow)
    om = np.gradient(theta, 1 / FS)
    al = np.gradient(om, 1 / FS)
    tau = K0 * k_factor * theta + B0 * om + I0 * al
    tau = tau + 0.002 * np.std(tau) * rng.standard_normal(n)
    return lf.PositionRecord(theta[:, None], tau[:, None], FS, name="known"), t


def _fit(rec, name):
    cfg = lf.FitConfig(n_jackknife=0, grid=8)
    preps = lf.prepare([rec], cfg)
    nom = lf.fit_nominal(preps, cfg)
    return lf.fit_effect(preps, name, nom, cfg, intervals=False)


def test_saturating_drift_known_answer():
    t = np.arange(int(FS * DUR)) / FS
    rec, _ = _record(1 + 0.8 * (1 - np.exp(-t / 6.0)))
    f = _fit(rec, "stiffness_saturating")
    assert f.params["change_rel"] == pytest.approx(0.8, rel=0.15)
    assert f.params["time_constant_s"] == pytest.approx(6.0, rel=0.25)
    assert f.split["rule"] == "interleaved blocks"
    assert f.held_out_reduction > 0.8


def test_switching_known_answer():
    t = np.arange(int(FS * DUR)) / FS
    rec, _ = _record(np.where((t // 4.0) % 2 == 1, 2.0, 1.0))
    f = _fit(rec, "stiffness_switching")
    assert f.params["level_ratio"] == pytest.approx(2.0, rel=0.15)
    assert f.held_out_reduction > 0.6


@pytest.mark.parametrize("period, start_high", [(4.0, False), (4.0, True), (5.0, True)])
def test_switching_counts_the_known_number_of_switches(period, start_high):
    """n_changes is the number of switches of the square wave: a record that starts (or
    ends) at the high level was counted one too many (the filter-trimmed first window,
    left out of the fit, was set to the low level)."""
    t = np.arange(int(FS * DUR)) / FS
    high = (t // period) % 2 == 1
    if start_high:
        high = ~high
    truth = int(np.count_nonzero(high[1:] != high[:-1]))
    assert truth == (8 if period == 4.0 else 7)
    rec, _ = _record(np.where(high, 2.0, 1.0))
    f = _fit(rec, "stiffness_switching")
    assert f.params["n_changes"] == truth
    assert f.params["level_ratio"] == pytest.approx(2.0, rel=0.15)


def test_the_switching_indicator_does_not_depend_on_the_split_swapped_in():
    """The change points are read from the record's usable samples whichever split is in
    place when they are first asked for: a stratified split drops held-out samples, and
    re-scoring a switching alternative there gave another indicator (fewer changes) than
    its own fit had, depending on which fit asked first."""
    t = np.arange(int(FS * DUR)) / FS
    rec, _ = _record(np.where((t // 4.0) % 2 == 1, 2.0, 1.0))
    cfg = lf.FitConfig(n_jackknife=0, grid=8)
    first, later = lf.prepare([rec], cfg)[0], lf.prepare([rec], cfg)[0]
    own = vary.basis(first, "stiffness_switching", {})[0].copy()
    changes = first._switch_changes
    cal, held = later.cal.copy(), later.held.copy()
    held[: later.Nd // 2] = False   # a split holding fewer samples (as a stratified one)
    cal[: later.Nd // 4] = False
    with vary.swapped([later], [(cal, held)]):
        swapped = vary.basis(later, "stiffness_switching", {})[0].copy()
    np.testing.assert_array_equal(swapped, own)
    assert later._switch_changes == changes


def test_the_cached_basis_is_the_basis():
    """vary.basis keeps the last few bases per record: the same arrays as computed anew,
    for every parameter value asked for in turn."""
    t = np.arange(int(FS * DUR)) / FS
    rec, _ = _record(1 + 0.8 * (1 - np.exp(-t / 6.0)))
    pr = lf.prepare([rec], lf.FitConfig(n_jackknife=0, grid=8))[0]
    for T in (2.0, 3.0, 2.0, 4.0, 5.0, 6.0, 7.0, 2.0):
        got = vary.basis(pr, "stiffness_saturating", {"time_constant_s": T})[0]
        np.testing.assert_array_equal(got, vary._basis(pr, "stiffness_saturating",
                                                       {"time_constant_s": T})[0])


def test_modulated_known_answer():
    t = np.arange(int(FS * DUR)) / FS
    rec, _ = _record(1 + 0.4 * np.sin(2 * np.pi * t / 9.0 + 0.5))
    f = _fit(rec, "stiffness_modulated")
    assert f.params["amplitude_rel"] == pytest.approx(0.4, rel=0.15)
    assert f.params["period_s"] == pytest.approx(9.0, rel=0.1)
    assert f.held_out_reduction > 0.8


def test_angle_known_answer_and_stratified_split():
    t = np.arange(int(FS * DUR)) / FS
    slow = 0.25 * np.sin(2 * np.pi * t / 12.0)
    rec, _ = _record(1 + 2.0 * slow, theta_slow=slow)
    rec.scheduling = SimpleNamespace(name="angle", values=slow)
    f = _fit(rec, "stiffness_angle")
    assert f.params["slope_rel"] == pytest.approx(2.0, rel=0.15)
    assert f.split["rule"] == "stratified by the scheduling variable"
    assert f.held_out_reduction > 0.8


def test_state_effect_needs_a_schedule():
    rec, _ = _record(1.0)
    rec.scheduling = None
    preps = lf.prepare([rec], lf.FitConfig(n_jackknife=0))
    names = lf.candidates(preps)
    assert "stiffness_angle" not in names and "stiffness_torque" not in names
    assert "stiffness_saturating" in names


def _stub(effect, red):
    return SimpleNamespace(effect=effect, held_out_reduction=red, at_search_bound=[])


def test_nesting_prefers_the_simpler_unless_richer_adds():
    fits = vary.prefer_simpler([_stub("stiffness_saturating", 0.95),
                                _stub("stiffness_drift", 0.9)])
    assert fits[0].effect == "stiffness_drift"
    fits = vary.prefer_simpler([_stub("stiffness_saturating", 0.95),
                                _stub("stiffness_drift", 0.3)])
    assert fits[0].effect == "stiffness_saturating"


PILOT = (__import__("pathlib").Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
         / "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat")


@pytest.mark.skipif(not PILOT.is_file(), reason="no ../shared/data/reklab-pilot/")
def test_pilot_stiffness_with_angle_on_sv():
    """The measured moving ankle: the state effect is scheduled on the nldat ``sv``, judged
    on the stratified split, and closes part of the held-out gap (20 % measured: the rest
    of the gap lies above 10 Hz, docs/diagnosis.md), stiffness rising with the angle."""
    import warnings

    import trialformat as tf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trials = tf.read_trials_mat(str(PILOT))
    recs = [lf.PositionRecord.from_trial(t) for t in trials]
    assert recs[0].scheduling.name == "sv"
    for r in recs:
        r.tau = -r.tau  # the sign the diagnosis's convention check corrects (K > 0)
    cfg = lf.FitConfig(n_jackknife=0)
    preps = lf.prepare(recs, cfg)
    nom = lf.fit_nominal(preps, cfg)
    f = lf.fit_effect(preps, "stiffness_angle", nom, cfg, intervals=False)
    assert f.split["rule"] == "stratified by the scheduling variable"
    # 20 % with the floor read above the band; 56 % with the non-coherent floor (issue 21
    # item 1: the torque not coherent with the motion left the gap, the effect closes a
    # larger share of what is left)
    assert 0.1 < f.held_out_reduction < 0.7
    assert f.params["slope_rel"] > 0
