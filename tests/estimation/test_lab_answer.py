"""One answer, a band from the data, conventions found, time-varying data flagged (issue 17).

Known-answer signals generated here in the frequency domain (exact derivatives of a
periodic, band-limited angle), independent of estimation.synthetic.
"""

import numpy as np
import pytest

import trialformat as tf
from estimation.accuracy import data_weights, fit_second_order, neighbour_mean
from estimation.lab import (AnalysisOptions, Unit, analyse, effective_averages,
                            frf_confidence)
from estimation.labreport import bode, stretch_phase_deg
from estimation.synthetic import position_trial

FS = 1000.0
ANKLE = {"K": 150.0, "B": 1.5, "I": 0.015}


def _trial(theta, tau, name="synthetic"):
    meta = tf.default_metadata(1)
    meta.update(fs=FS, n_dof=1, perturbed_dof=1, posture_deg=[0.0],
                source="test: frequency-domain position perturbation")
    meta["perturbation"] = {"kind": "position"}
    meta["sensors"].update(torque_sampling="instantaneous")
    n = len(theta)
    return tf.Trial(meta=meta, t=np.arange(n) / FS, theta=theta[:, None],
                    tau_h=tau[:, None], name=name)


def _angle(n, seed, lo_hz, hi_hz, rms=0.02):
    """Periodic angle with a flat spectrum on lo_hz < f <= hi_hz, zero elsewhere, and
    its first two time derivatives (exact on the DFT grid)."""
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1 / FS)
    X = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * \
        ((f > lo_hz) & (f <= hi_hz))
    s = 2j * np.pi * f
    x, dx, ddx = (np.fft.irfft(X * s ** p, n) for p in (0, 1, 2))
    scale = rms / x.std()
    return f, X * scale, x * scale, dx * scale, ddx * scale


def _noise(rng, f, n, amplitude):
    """Gaussian noise whose DFT magnitude follows ``amplitude(f)`` (same scaling as X)."""
    N = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * amplitude
    return np.fft.irfft(N, n)


def _fast(**kw):
    return AnalysisOptions(sensitivity=False, segments=0, **kw)


# ----------------------------------------------------------------------------- one answer


def test_neighbour_mean_excludes_the_bin_and_its_two_neighbours():
    x = np.arange(20.0)
    m = neighbour_mean(x)
    # bin 10: bins 4..7 and 13..16 -> mean 10; bin 0: bins 3..6 -> 4.5; bin 19: 13..16
    assert m[10] == pytest.approx(10.0)
    assert m[0] == pytest.approx(4.5)
    assert m[19] == pytest.approx(14.5)
    spike = np.zeros(20)
    spike[10] = 1.0
    assert neighbour_mean(spike)[8:13].tolist() == [0.0] * 5   # the bin never weighs itself


def test_default_fit_is_one_weighted_least_squares_of_an_independent_solver():
    """The lab fit equals numpy's lstsq on the same bins with weights built here."""
    r = analyse(Unit("a", [position_trial(**ANKLE, seed=3, record_reference=False)], ""),
                _fast())
    band = (r.f > r.band_hz[0]) & (r.f <= r.band_hz[1])
    z, w = r.Z[band, 0, 0], 2 * np.pi * r.f[band]
    logm = np.log(np.abs(z))
    wt = np.empty(z.size)
    for k in range(z.size):                       # neighbours 3..6 bins away, by hand
        idx = [j for j in range(k - 6, k + 7) if 2 < abs(j - k) and 0 <= j < z.size]
        wt[k] = 1 / np.exp(np.mean(logm[idx]))
    A = np.stack([-w ** 2, w * 1j, np.ones_like(w)], axis=1) * wt[:, None]
    theta = np.linalg.lstsq(np.vstack([A.real, A.imag]),
                            np.concatenate([(z * wt).real, (z * wt).imag]), rcond=None)[0]
    assert theta == pytest.approx([r.fit.M[0, 0], r.fit.B[0, 0], r.fit.K[0, 0]], rel=1e-9)


def test_repeated_runs_give_the_same_numbers():
    trial = position_trial(**ANKLE, seed=5)
    a, b = (analyse(Unit("a", [trial], "")) for _ in range(2))
    for p in ("M", "B", "K", "M_ci", "B_ci", "K_ci"):
        assert np.array_equal(getattr(a.fit, p), getattr(b.fit, p))
    assert a.sensitivity == b.sensitivity and a.segments == b.segments


def test_smoothed_weights_remove_the_bias_of_weights_from_the_bin_itself():
    """1/|Zhat| of the bin itself favours bins where noise shrank |Zhat| (-0.7 % on K,
    docs/estimation.md); neighbour weights do not. Paired over 20 seeds."""
    rel, smo = [], []
    for seed in range(20):
        unit = Unit("a", [position_trial(**ANKLE, seed=seed)], "")
        rel.append(analyse(unit, _fast(weighting="relative")).fit.K[0, 0])
        smo.append(analyse(unit, _fast(weighting="smoothed")).fit.K[0, 0])
    rel, smo = np.array(rel) / ANKLE["K"] - 1, np.array(smo) / ANKLE["K"] - 1
    assert np.mean(rel - smo) < -0.004                 # the relative weights' bias
    assert abs(np.mean(smo)) < 0.4 * np.std(smo)       # no bias beyond the scatter / 2.2


def test_coherence_weights_follow_bendat_piersol():
    z = np.full(30, 2.0 + 0j)
    g2 = np.full(30, 0.9)
    assert data_weights(z, "coherence", g2) == pytest.approx(np.sqrt(0.9 / 0.1) / 2.0)
    with pytest.raises(Exception, match="coherence"):
        fit_second_order(np.arange(30.0), z, band_hz=(0, 30), weighting="coherence")


# ----------------------------------------------------------------------------- data band


def test_default_band_is_where_the_perturbation_has_power_and_coherence_is_high():
    """Angle flat on 2-100 Hz; torque noise whose spectrum makes the true coherence
    1 / (1 + (f / 30)^4 / 9): 0.9 at 30 Hz. The band: 2 Hz to about 30 Hz."""
    n = 120_000
    f, X, x, dx, ddx = _angle(n, 1, 2.0, 100.0)
    rng = np.random.default_rng(2)
    Zf = ANKLE["K"] + 2j * np.pi * f * ANKLE["B"] - ANKLE["I"] * (2 * np.pi * f) ** 2
    ratio = np.sqrt(np.clip((f / 30.0) ** 4 / 9.0, 1e-12, None))
    tau = ANKLE["K"] * x + ANKLE["B"] * dx + ANKLE["I"] * ddx + \
        _noise(rng, f, n, np.abs(Zf * X) * ratio / np.sqrt(2) * ((f > 2) & (f <= 100)))
    r = analyse(Unit("a", [_trial(x, tau)], ""), _fast())
    lo, hi = r.band_hz
    assert r.band_source.startswith("from the data")
    assert 1.5 <= lo <= 2.0 and 26.0 <= hi <= 36.0, r.band_hz
    # a perturbation without power above 25 Hz: the band stops there
    f, X, x, dx, ddx = _angle(n, 3, 0.0, 25.0)
    tau = ANKLE["K"] * x + ANKLE["B"] * dx + ANKLE["I"] * ddx + \
        0.01 * np.random.default_rng(4).standard_normal(n)
    r = analyse(Unit("a", [_trial(x, tau)], ""), _fast())
    # (the Hann window leaks the power edge by about two bins, 0.24 Hz)
    assert r.band_hz[0] == 0.0 and 24.0 <= r.band_hz[1] <= 25.0 + 3 * FS / 8192, r.band_hz


def test_a_poor_user_band_gets_a_suggestion_that_works():
    trial = position_trial(**ANKLE, seed=7, record_reference=False)
    r = analyse(Unit("a", [trial], ""), AnalysisOptions(band_hz=(0.0, 3.0)))
    assert any("poorly determined" in w for w in r.warnings)
    tip = [w for w in r.warnings if w.startswith("suggested band: --band")]
    assert tip, r.warnings
    lo, hi = (float(v) for v in tip[0].split("--band ")[1].split(" ")[:2])
    good = analyse(Unit("a", [trial], ""), AnalysisOptions(band_hz=(lo, hi)))
    assert not any("poorly determined" in w or w.startswith("poor fit")
                   for w in good.warnings), good.warnings


# ----------------------------------------------------------------------------- conventions


def test_reversed_torque_sign_is_named_with_the_key_to_declare():
    trial = position_trial(**ANKLE, seed=8)
    flipped = tf.Trial(**{**trial.__dict__, "tau_h": -trial.tau_h})
    r = analyse(Unit("a", [flipped], ""), _fast())
    sign = [w for w in r.warnings if w.startswith("torque sign reversed?")]
    assert sign and '"torque_sign": -1' in sign[0] and "phase" in sign[0], r.warnings
    assert "torque sign reversed?" in r.flags
    ok = analyse(Unit("a", [trial], ""), _fast())
    assert not any(w.startswith("torque sign") for w in ok.warnings)


def test_absolute_angles_are_named_with_the_key_to_declare():
    trial = position_trial(**ANKLE, seed=9)
    shifted = tf.Trial(**{**trial.__dict__, "theta": trial.theta + 0.3,
                          "theta_ref": trial.theta_ref + 0.3})
    r = analyse(Unit("a", [shifted], ""), _fast())
    assert any(w.startswith("absolute angles?") and '"angles": "absolute"' in w
               for w in r.warnings), r.warnings
    ok = analyse(Unit("a", [trial], ""), _fast())
    assert not any(w.startswith("absolute") for w in ok.warnings)
    assert ok.fit.K[0, 0] == pytest.approx(r.fit.K[0, 0], rel=1e-9)   # mean removed


# ----------------------------------------------------------------------------- time-varying


def _ramp_trial(k0, k1, seed):
    n = 60_000
    f, X, x, dx, ddx = _angle(n, seed, 0.0, 40.0)
    K = np.linspace(k0, k1, n)
    tau = K * x + ANKLE["B"] * dx + ANKLE["I"] * ddx + \
        0.05 * np.random.default_rng(seed + 1).standard_normal(n)
    return _trial(x, tau, name=f"ramp{k0:g}-{k1:g}")


def test_a_stiffness_ramp_is_flagged_with_segment_estimates():
    r = analyse(Unit("a", [_ramp_trial(100.0, 200.0, 11)], ""))
    tv = [w for w in r.warnings if w.startswith("time-varying: K")]
    assert tv and "linear drift" in tv[0] and "blocks" in tv[0], r.warnings
    ks = [s["K"][0][0] for s in r.segments]
    assert len(ks) == 4 and np.all(np.diff(ks) > 0)           # rising, as the ramp
    assert ks[0] == pytest.approx(112.5, rel=0.05) and ks[-1] == pytest.approx(187.5, rel=0.05)
    assert "time-varying" in r.flags


def test_a_constant_stiffness_is_not_flagged():
    for seed in (21, 23, 25):
        r = analyse(Unit("a", [_ramp_trial(150.0, 150.0, seed)], ""))
        assert not any(w.startswith("time-varying") for w in r.warnings), r.warnings
        assert not any(w.startswith("band-sensitive") for w in r.warnings), r.warnings


def test_a_model_that_does_not_hold_is_band_sensitive():
    """Z = K + B s + I s^2 + 80 / (1 + s / (2 pi 3 Hz)): a stiffness that fades above
    3 Hz (a reflex-like low-pass path). Its K depends on the band."""
    n = 60_000
    f, X, x, dx, ddx = _angle(n, 31, 0.0, 40.0)
    s = 2j * np.pi * f
    extra = np.fft.irfft(X * 80.0 / (1 + s / (2 * np.pi * 3.0)), n)
    tau = ANKLE["K"] * x + ANKLE["B"] * dx + ANKLE["I"] * ddx + extra + \
        0.05 * np.random.default_rng(32).standard_normal(n)
    r = analyse(Unit("a", [_trial(x, tau)], ""))
    assert any(w.startswith("band-sensitive: K") for w in r.warnings), r.warnings
    lo, hi = r.sensitivity["range"]["K"][0][0][0], r.sensitivity["range"]["K"][1][0][0]
    assert hi - lo > 2 * r.fit.K_ci[0, 0]


def test_a_practically_irrelevant_band_dependence_is_not_flagged():
    """A reflex-like stiffness of 0.3 N m/rad (0.2 % of K) with almost no noise: K moves
    with the band beyond its tiny interval, but by far less than BAND_MIN_SPREAD of its
    value, so nothing is flagged (it was: "I = 0.015 +- 9.6e-07 moves over 0.014995...")."""
    from estimation.lab import BAND_MIN_SPREAD
    n = 60_000
    f, X, x, dx, ddx = _angle(n, 31, 0.0, 40.0)
    s = 2j * np.pi * f
    extra = np.fft.irfft(X * 0.3 / (1 + s / (2 * np.pi * 3.0)), n)
    tau = ANKLE["K"] * x + ANKLE["B"] * dx + ANKLE["I"] * ddx + extra + \
        1e-5 * np.random.default_rng(32).standard_normal(n)
    r = analyse(Unit("a", [_trial(x, tau)], ""))
    lo, hi = r.sensitivity["range"]["K"][0][0][0], r.sensitivity["range"]["K"][1][0][0]
    assert hi - lo > 2 * r.fit.K_ci[0, 0]                  # statistically it moves...
    assert hi - lo < BAND_MIN_SPREAD * r.fit.K[0, 0]       # ...by a negligible amount
    assert not any(w.startswith("band-sensitive") for w in r.warnings), r.warnings
    assert "band-sensitive" not in r.flags


# ----------------------------------------------------------------------------- plots


def test_frf_confidence_and_equivalent_averages_known_answers():
    # Hann, 75 % overlap: correlations 0.659, 0.167, 0.0075 of segments 1-3 steps apart
    # (Harris 1978, Table 1: overlap correlation 65.9 %, 16.7 %)
    big = effective_averages(10_000, {"nperseg": 8192, "noverlap": 6144, "window": "hann"})
    assert 10_000 / big == pytest.approx(1 + 2 * (0.659 ** 2 + 0.167 ** 2 + 0.0075 ** 2),
                                         rel=2e-3)
    assert effective_averages(20, {"nperseg": 256, "noverlap": 0, "window": "hann"}) == 20
    e = frf_confidence(np.array([0.9]), 26, 0.95)[0]
    assert e == pytest.approx(1.959964 * np.sqrt(0.1) / np.sqrt(0.9 * 52), rel=1e-6)


def test_phase_is_unwrapped_per_coherent_stretch_not_through_gaps():
    f = np.linspace(1, 50, 400)
    ph = -np.radians(4.0) * f * 10                      # down to -1960 deg
    z = np.exp(1j * ph)
    c = np.ones(f.size)
    c[150:200] = 0.1                                     # a coherence gap
    out = stretch_phase_deg(z, c, np.degrees(ph))
    assert np.all(np.isnan(out[150:200]))
    assert np.allclose(out[:150], np.degrees(ph[:150]))
    assert np.allclose(out[200:], np.degrees(ph[200:]))  # aligned to the reference
    assert np.all(np.abs(np.diff(out[200:])) < 10)


def test_bode_covers_the_coherent_range_and_flags_a_poor_fit():
    trial = position_trial(**ANKLE, seed=12)
    flipped = tf.Trial(**{**trial.__dict__, "tau_h": -trial.tau_h})
    r = analyse(Unit("a", [flipped], ""), AnalysisOptions(band_hz=(0.0, 5.0)))
    assert r.f_max > 30.0                                # not 2 x the band top
    cols = r.frf_table()
    assert cols["f_Hz"].max() == pytest.approx(r.f_max)
    assert np.all(cols["Z11_mag_lo"] <= cols["Z11_mag"]) and \
        np.all(cols["Z11_mag"] <= cols["Z11_mag_hi"])
    fig = bode(r)
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any(t.startswith("FLAGGED") and "non-physical" in t for t in texts), texts
    import matplotlib.pyplot as plt
    plt.close(fig)
