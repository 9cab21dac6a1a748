"""The position experiment's effect fits on worker processes (diagnosis.tasks.task_limbfit)
give the fits of the one-process path bit for bit; a fit rebuilt from its record
(limbfit.fit_record / fit_from_record: a resumed diagnosis, a worker's result) keeps the
objective's scale of a varying effect, so its jackknife intervals are the same."""

import uuid

import numpy as np
import pytest
from scipy import signal as sps

import trialformat as tf
from diagnosis import limb as lm
from diagnosis import limbfit as lf
from diagnosis.config import DiagnosisConfig
from diagnosis.experiments.position import PositionServo
from diagnosis.parallel import Runner
from diagnosis.pipeline.resume import ResumeStore
from diagnosis.tasks import TaskState

FS, N = 500.0, 12000
K1, B1, I1 = 30.0, 0.5, 0.02


def _reflex_trial():
    """A limb with a stretch reflex (known answer) under a measured-angle drive."""
    rng = np.random.default_rng(5)
    sos = sps.butter(4, 8.0, fs=FS, output="sos")
    theta = sps.sosfiltfilt(sos, rng.standard_normal(N))[:, None]
    theta *= 0.015 / theta.std()
    limb = lm.LimbModel(K=np.array([[K1]]), B=np.array([[B1]]), I=np.array([[I1]]))
    truth = {"gain": 3.0, "delay_s": 0.04, "frequency_hz": 4.0, "rectified": False}
    tau = lm.limb_torque(theta, FS, limb, {"stretch_reflex": truth})
    tau = tau + 0.02 * rng.standard_normal(tau.shape)
    meta = tf.default_metadata(1)
    meta.update(fs=FS, perturbation={"kind": "position"},
                sensors={"torque_sampling": "instantaneous"})
    return tf.Trial(meta=meta, t=np.arange(N) / FS, theta=theta, tau_h=tau, name="reflex")


def _fields(fit):
    return (fit.effects, fit.params, fit.calibration_gap, fit.held_out_gap, fit.objective,
            fit.n_evaluations, fit.intervals, fit.split, fit.at_search_bound,
            fit.model.K.tolist(), fit.model.B.tolist(), fit.model.M.tolist())


def test_fits_on_two_workers_equal_the_one_process_fits(tmp_path):
    trials = [_reflex_trial()]
    effects = ("stiffness_saturating", "torque_sensor_lag", "wobbling_mass")
    config = DiagnosisConfig()
    exp = PositionServo(trials)
    serial = exp.fit_effects(trials, effects, config)
    state = TaskState(token=uuid.uuid4().hex, trials=trials, experiment=exp, model=None,
                      config=config, plant=None, cal=[], held=[])
    store = ResumeStore(tmp_path, "k")
    with Runner(state, workers=2) as runner:
        parallel = exp.fit_effects(trials, effects, config, store=store, runner=runner)
        phases = [p for p in runner.timings if p["phase"] == "limbfit effects"]
        # a re-run reads every fit (and the best fit's intervals) back from the store
        again_store = ResumeStore(tmp_path, "k")
        again = exp.fit_effects(trials, effects, config, store=again_store, runner=runner)
    # the fits, the best fit's jackknife and the pair search (diagnosis.limbpairs)
    assert store.n_stored == len(effects) + 2 and again_store.n_reused == len(effects) + 2
    assert [_fields(f) for f in again["pairs"]] == [_fields(f) for f in parallel["pairs"]]
    assert [_fields(f) for f in again["fits"]] == [_fields(f) for f in parallel["fits"]]
    assert phases and phases[0]["tasks"] == len(effects)  # fitted on the workers
    assert serial["significant"] and len(serial["fits"]) == len(effects)
    assert serial["fits"][0].intervals  # the best fit's jackknife, from a rebuilt record
    assert [_fields(f) for f in parallel["fits"]] == [_fields(f) for f in serial["fits"]]
    assert parallel["g0_held"] == serial["g0_held"]


def test_a_varying_fit_rebuilt_from_its_record_keeps_its_objective_scale():
    t = np.arange(N) / FS
    trial = _reflex_trial()
    theta = trial.theta[:, 0]
    om = np.gradient(theta, 1 / FS)
    tau = K1 * (1 + 0.8 * (1 - np.exp(-t / 6.0))) * theta + B1 * om
    rec = lf.PositionRecord(theta[:, None], tau[:, None], FS, name="drift")
    cfg = lf.FitConfig(n_jackknife=3, grid=6)
    preps = lf.prepare([rec], cfg)
    nominal = lf.fit_nominal(preps, cfg)
    fit = lf.fit_effect(preps, "stiffness_saturating", nominal, cfg, intervals=False)
    again = lf.fit_from_record(preps, lf.fit_record(fit), nominal, cfg)
    assert again._problem[0].unit == fit._problem[0].unit
    assert again._problem[0].unit != pytest.approx(nominal["solution"].cal_energy)
    lf.add_intervals(fit, cfg)
    lf.add_intervals(again, cfg)
    assert again.intervals == fit.intervals


def test_pairs_and_ties_on_two_workers_equal_the_one_process_ones():
    """The pairs' forward choices and joint refits (diagnosis.limbpairs) and the ties'
    scores on the named fit's split (diagnosis.limbties) run as tasks on the workers
    (tasks.task_limbfit_call): the same pairs and alternatives, bit for bit, as in one
    process. A reflex over a 10 ms channel delay (labsim): a pair is named, and the
    time-varying alternative is scored on the pair's (default) split."""
    import dataclasses

    import labsim
    spec = labsim.draw("channel_delay+reflex", np.random.default_rng(1), duration_s=15.0)
    spec = dataclasses.replace(spec, record_reference=False, perturbation=dataclasses.replace(
        spec.perturbation, kind="noise"))
    spec.sensors.tau.delay_s = 0.010
    trials = [labsim.simulate(spec).trial]
    effects = ("stretch_reflex", "channel_delay", "stiffness_saturating")
    config = DiagnosisConfig()
    exp = PositionServo(trials)
    serial = exp.fit_effects(trials, effects, config)
    assert serial["pairs"] and serial["pairs"][0].effects[:1] == ("stretch_reflex",)
    alt_serial = serial["alternatives"](serial["pairs"][0])
    state = TaskState(token=uuid.uuid4().hex, trials=trials, experiment=exp, model=None,
                      config=config, plant=None, cal=[], held=[])
    with Runner(state, workers=2) as runner:
        parallel = exp.fit_effects(trials, effects, config, runner=runner)
        alt_parallel = parallel["alternatives"](parallel["pairs"][0])
        phases = {p["phase"]: p["tasks"] for p in runner.timings}
    assert phases.get("limbfit pairs", 0) >= 2 and phases.get("limbfit pair refits", 0) >= 1
    assert phases.get("limbties scores", 0) >= 1
    assert [_fields(f) for f in parallel["pairs"]] == [_fields(f) for f in serial["pairs"]]
    assert [f.second_test for f in parallel["pairs"]] == [f.second_test
                                                          for f in serial["pairs"]]
    assert any(r["rescored"] for r in alt_serial["rows"])
    assert alt_parallel == alt_serial
