"""The experiment interface, one-joint and position experiments, the limb estimate's
sampling handling, and the report folder's data safety (issues 14 and 16)."""

import os
import stat

import numpy as np
import pytest

import trialformat as tf
from diagnosis import DiagnosisInputError, diagnose
from diagnosis.arm import estimate_arm
from diagnosis.experiments import (ExoskeletonIMBIC, PositionServo, RenderedImpedance,
                                   experiment_for)
from estimation.synthetic import position_trial, synthetic_trial, torque_trial

K1, B1, I1 = 60.0, 0.8, 0.012


def _write(folder, trials):
    folder.mkdir(parents=True, exist_ok=True)
    for t in trials:
        tf.write_trial(folder / t.name, t)
    return folder


def test_experiment_for_picks_the_apparatus(make_linear_trial):
    assert isinstance(experiment_for([position_trial(K=K1, B=B1, I=I1, duration_s=10)]),
                      PositionServo)
    assert isinstance(experiment_for([torque_trial(K=K1, B=B1, I=I1, duration_s=10)]),
                      RenderedImpedance)
    assert isinstance(experiment_for([make_linear_trial()]), ExoskeletonIMBIC)
    mixed = [position_trial(K=K1, B=B1, I=I1, duration_s=10, name="p"),
             torque_trial(K=K1, B=B1, I=I1, duration_s=10, name="q")]
    with pytest.raises(DiagnosisInputError, match="different perturbation kinds"):
        experiment_for(mixed)


def test_position_experiment_signals_and_effects():
    with_ref = position_trial(K=K1, B=B1, I=I1, duration_s=10)
    without = position_trial(K=K1, B=B1, I=I1, duration_s=10, record_reference=False)
    exp = experiment_for([without])
    assert exp.perturbation_signal(without) == "theta"
    assert exp.output_signals(without) == ("tau_h",)
    assert exp.perturbation_signal(with_ref) == "theta_ref"
    applicable = exp.applicable_effects(("friction", "stretch_reflex", "torque_sensor_lag"))
    assert applicable == ("stretch_reflex", "torque_sensor_lag")


def test_one_joint_metadata_is_not_filled_from_the_two_joint_reference():
    meta = tf.default_metadata(1)
    assert "robot" not in meta and "controller" not in meta and "posture_deg" not in meta
    assert meta["friction"]["Fc"] == [0.0]
    trial = torque_trial(K=K1, B=B1, I=I1, duration_s=10)
    del trial.meta["controller"]["B_rd"]
    with pytest.raises(DiagnosisInputError, match=r"controller\.B_rd"):
        experiment_for([trial])


def test_limb_estimate_follows_the_declared_sampling():
    """2048 Hz, tau_h sampled at the instant (declared): the estimate's B is right; the
    left-limit delay applied regardless (the earlier behaviour) biases it."""
    fs = 2048.0
    trials = [synthetic_trial(perturbed_dof=k, fs=fs, duration_s=24.0, seed=k,
                              sampling="instant") for k in (1, 2)]
    assert all(t.meta["sensors"]["torque_sampling"] == "instantaneous" for t in trials)
    arm = estimate_arm(trials)
    from trialformat import reference as ref
    _, B_true, K_true = ref.arm_matrices()
    assert arm.sampling_delay == 0.0
    np.testing.assert_allclose(np.diag(arm.B), np.diag(B_true), rtol=0.006)
    np.testing.assert_allclose(np.diag(arm.K), np.diag(K_true), rtol=0.006)
    for t in trials:  # the same data declared left-limit: the delay is applied
        t.meta["sensors"]["torque_sampling"] = "left_limit"
    biased = estimate_arm(trials)
    assert biased.sampling_delay == pytest.approx(0.5 / fs)
    # B biased by M w^2 tau (about 2 % at 2048 Hz in the 1-20 Hz band), 4x the error above
    assert np.max(np.abs(np.diag(biased.B) / np.diag(B_true) - 1)) > 0.015


def test_one_joint_torque_trial_is_diagnosed(tmp_path):
    trials = [torque_trial(K=K1, B=B1, I=I1, duration_s=40.0, seed=s, name=f"tq{s}")
              for s in (1, 2)]
    for t in trials:  # one limb: labelled (unlabelled recordings of one joint stay apart)
        t.meta["condition"] = "limb"
    report = diagnose(_write(tmp_path / "in", trials), tmp_path / "out", workers=1,
                      progress=False)
    assert report.experiment["class"] == "RenderedImpedance"
    assert report.verdict == "no significant gap", report.summary
    assert abs(report.arm["K_h"][0][0] / K1 - 1) < 0.05


def test_position_trial_nominal_and_resume_and_safety(tmp_path):
    # no voluntary torque: with it, the archived (angle-driven) experiment has a real,
    # unmodelled gap (the limb's own torque moves the joint)
    trial = position_trial(K=K1, B=B1, I=I1, duration_s=40.0, record_reference=False,
                           torque_sign=-1, voluntary_rms_nm=0.0, name="ankle")
    folder = _write(tmp_path / "in", [trial])
    out = tmp_path / "out"
    old = os.umask(0o022)
    try:
        first = diagnose(folder, out, workers=1, progress=False)
    finally:
        os.umask(old)
    assert first.experiment["class"] == "PositionServo"
    assert first.verdict == "no significant gap", first.summary
    # declared torque_sign -1 is applied by the reader (a finding, no mismatch)
    assert any(c["name"].startswith("declared") for c in first.conventions)
    mode = stat.S_IMODE((out / "report.json").stat().st_mode)
    assert mode == 0o644, oct(mode)
    assert stat.S_IMODE(out.stat().st_mode) == 0o755
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]
    second = diagnose(folder, out, workers=1, progress=False)
    assert second.timing["resumed_tasks"] == 1  # the nominal run, stored by the first
    assert second.verdict == first.verdict
    assert second.gap["nominal_all"] == first.gap["nominal_all"]
    # an out folder holding other files, or the trials' own folder, is refused
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(DiagnosisInputError, match="not a diagnosis report"):
        diagnose(folder, other, workers=1, progress=False)
    with pytest.raises(DiagnosisInputError, match="trials' folder"):
        diagnose(folder, folder, workers=1, progress=False)
    assert (other / "notes.txt").read_text() == "mine"


def test_position_reflex_is_named(tmp_path):
    """A limb with a stretch reflex (diagnosis.limb, known answer) under a measured-angle
    drive: the reflex is named, its delay within 20 %, the held-out gap shrinks."""
    from diagnosis import limb as lm
    fs, n = 1000.0, 40000
    rng = np.random.default_rng(3)
    from scipy import signal as sps
    sos = sps.butter(4, 8.0, fs=fs, output="sos")
    theta = sps.sosfiltfilt(sos, rng.standard_normal(n))[:, None]
    theta *= 0.015 / theta.std()
    truth = {"gain": 3.0, "delay_s": 0.045, "frequency_hz": 4.0, "rectified": False}
    limb = lm.LimbModel(K=np.array([[K1]]), B=np.array([[B1]]), I=np.array([[I1]]))
    tau = lm.limb_torque(theta, fs, limb, {"stretch_reflex": truth})
    tau = tau + 0.02 * rng.standard_normal(tau.shape)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, perturbation={"kind": "position"},
                sensors={"torque_sampling": "instantaneous"})
    trial = tf.Trial(meta=meta, t=np.arange(n) / fs, theta=theta, tau_h=tau, name="reflex")
    report = diagnose(_write(tmp_path / "in", [trial]), tmp_path / "out", workers=1,
                      progress=False)
    assert report.named == ["stretch_reflex"], report.summary
    assert report.fitted["stretch_reflex"]["delay_s"] == pytest.approx(0.045, rel=0.2)
    lo, hi = report.intervals["stretch_reflex"]["delay_s"]
    assert lo <= report.fitted["stretch_reflex"]["delay_s"] <= hi
    assert report.gap["named_held_out_reduction"] >= 0.7
    assert (tmp_path / "out" / "frf_compare.png").is_file()


def test_resume_store_round_trips_fits_runs_and_divergences(tmp_path, make_linear_trial):
    """What a killed run stored is read back as it was (no pickle), and a task stored is
    not run again."""
    import math

    from diagnosis.fitting import EffectFit
    from diagnosis.pipeline.resume import ResumeStore

    fit = EffectFit(("friction",), {"friction": {"Fc": 0.2}}, 0.5, 11, held_out_gap=math.inf,
                    objective=-0.1)
    trial = make_linear_trial(n_samples=9000)
    calls = []

    class Runner:
        def map(self, fn, args, desc="", done=None):
            out = []
            for i, a in enumerate(args):
                calls.append(a)
                out.append(fn(None, *a))
                done(i, out[-1])
            return out

    def task(state, i):
        return [fit, trial, None][i]

    store = ResumeStore(tmp_path, "k")
    first = store.map(Runner(), task, [(0,), (1,), (2,)], "t")
    again = ResumeStore(tmp_path, "k").map(Runner(), task, [(0,), (1,), (2,), (0,)], "t")
    assert len(calls) == 3  # the second store ran nothing
    assert again[0] == first[0] and again[3] == fit
    np.testing.assert_array_equal(again[1].theta, trial.theta)
    assert again[1].meta == trial.meta and again[2] is None
