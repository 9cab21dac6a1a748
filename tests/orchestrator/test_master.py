"""Master building blocks: rates, sampler, delay line, recorder, effects parsing."""

import math

import numpy as np
import pytest

from orchestrator import EffectError, RateError, parse_effects
from orchestrator.master import DelayLine, Recorder, Sampler, decimation


@pytest.mark.parametrize("step,expected", [(None, 1), (1e-3, 1), (1e-5, 100), (2.5e-4, 4)])
def test_decimation(step, expected):
    assert decimation(1e-3, step) == expected


@pytest.mark.parametrize("step", [3e-4, 2e-3, 0.0, -1e-5, float("nan")])
def test_uneven_rate_refused(step):
    with pytest.raises(RateError, match="communication step"):
        decimation(1e-3, step)


def test_sampler_quantises_encoder_in_degrees_and_torque():
    r_deg, r_tau = 7.031e-3, 0.02
    s = Sampler(2, math.radians(r_deg), r_tau)
    x = [0.0123456, -0.00061, 0.129, -0.031]
    got = s.sample(0, x)
    r = math.radians(r_deg)
    assert got[:2] == [r * round(x[0] / r), r * round(x[1] / r)]
    assert got[2:] == pytest.approx([0.12, -0.04], abs=1e-15)
    # half-way values round to even, as numpy
    assert Sampler(1, 0.0, 0.5).sample(0, [0.0, 0.25])[1] == 0.0


def test_sampler_adds_noise_before_quantisation():
    """Noise of 0.3 r on a value 0.4 r from a step: quantising first would always give 0;
    noise first crosses the step in a known fraction of samples."""
    r = 0.01
    noise = np.random.default_rng(0).normal(0, 0.3 * r, (20000, 1))
    s = Sampler(1, 0.0, r, theta_noise=np.zeros_like(noise), tau_noise=noise)
    out = np.array([s.sample(n, [0.0, 0.004])[1] for n in range(len(noise))])
    crossed = np.mean(out == r)
    expected = 0.5 * math.erfc((0.005 - 0.004) / (0.3 * r) / math.sqrt(2))
    assert crossed == pytest.approx(expected, abs=0.015)
    assert set(np.round(out / r).astype(int)) <= {-1, 0, 1, 2}


def test_ideal_sampler_is_identity():
    x = [0.1, 0.2, 0.3, 0.4]
    assert Sampler(2).sample(5, x) == x


def test_delay_line():
    line = DelayLine(2, 1)
    applied = [line.push([float(n)])[0] for n in range(5)]
    assert applied == [0.0, 0.0, 0.0, 1.0, 2.0]


def test_recorder_arrays():
    rec = Recorder(("a", "b"))
    for n in range(3):
        rec.record([n, -n], [2 * n])
    arr = rec.arrays()
    assert len(rec) == 3
    np.testing.assert_array_equal(arr["a"], [[0, 0], [1, -1], [2, -2]])
    np.testing.assert_array_equal(arr["b"], [[0], [2], [4]])


def test_effects_split_and_broadcast():
    eff = parse_effects({"delay": {"samples": 2}, "actuator_lag": {"time_constant_s": 0.004},
                         "sensor_noise": {"theta_noise_std_rad": 1e-5, "tau_noise_std_nm": 0.01},
                         "transmission_compliance": {"k_t": [500, 300], "c_t": 1.0},
                         "gravity": {"tilt_deg": -5}, "quantization":
                         {"encoder_resolution_deg": 0.01}}, 2)
    assert eff.delay_samples == 2
    assert eff.theta_noise_std == [1e-5, 1e-5] and eff.tau_noise_std == [0.01, 0.01]
    assert eff.encoder_resolution_deg == 0.01 and eff.torque_resolution_nm is None
    assert eff.plant_parameters == {
        "actuator_lag.time_constant_s": 0.004, "transmission_compliance.k_t[1]": 500.0,
        "transmission_compliance.k_t[2]": 300.0, "transmission_compliance.c_t[1]": 1.0,
        "transmission_compliance.c_t[2]": 1.0, "gravity.tilt_deg": -5.0}
    assert parse_effects(None, 2).plant_parameters == {}


@pytest.mark.parametrize("effects,match", [
    ({"backlash": {"width": 1}}, "unknown effect 'backlash'"),
    ({"delay": {"steps": 1}}, "no parameter 'steps'"),
    ({"delay": {"samples": 1.5}}, "integer"),
    ({"delay": {"samples": 0}}, "> 0"),
    ({"friction": {"Fc": [0.1, 0.2, 0.3]}}, "2 values"),
    ({"actuator_lag": {"time_constant_s": -1}}, ">= 0"),
    ({"sensor_noise": {"tau_noise_std_nm": float("nan")}}, "finite"),
    ({"gravity": 5}, "dict"),
])
def test_bad_effects(effects, match):
    with pytest.raises(EffectError, match=match):
        parse_effects(effects, 2)
