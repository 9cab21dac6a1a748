"""Position trials in any units, constant channels and options a position experiment
cannot use (the testers' defects 2-4 of the robustness round): known answers built here."""

import subprocess
import sys

import numpy as np
import pytest
from scipy import signal as sps

import trialformat as tf
from diagnosis import DiagnosisConfig, DiagnosisInputError, diagnose
from diagnosis import limb as lm
from estimation.synthetic import position_trial

FS = 1000.0
#: a few position effects (the fits dominate the run time): the reflex and two it competes with
CFG = DiagnosisConfig(effects=("stretch_reflex", "wobbling_mass", "channel_delay"))


def _reflex_trial(seconds=12.0, seed=3, name="z"):
    """A one-joint limb with a stretch reflex driven by a measured angle (a gap to name)."""
    n = int(seconds * FS)
    rng = np.random.default_rng(seed)
    sos = sps.butter(4, 8.0, fs=FS, output="sos")
    theta = sps.sosfiltfilt(sos, rng.standard_normal(n))[:, None]
    theta *= 0.015 / theta.std()
    limb = lm.LimbModel(K=[[60.0]], B=[[0.8]], I=[[0.012]])
    tau = lm.limb_torque(theta, FS, limb, {"stretch_reflex": {
        "gain": 3.0, "delay_s": 0.045, "frequency_hz": 4.0}})
    tau = tau + 0.02 * rng.standard_normal(tau.shape)
    theta = theta + 5e-6 * rng.standard_normal(theta.shape)
    meta = tf.default_metadata(1)
    meta.update(fs=FS, perturbation={"kind": "position"},
                sensors={"torque_sampling": "instantaneous"})
    return tf.Trial(meta=meta, t=np.arange(n) / FS, theta=theta, tau_h=tau, name=name)


def _write(folder, trial):
    folder.mkdir(parents=True, exist_ok=True)
    tf.write_trial(folder / trial.name, trial)
    return folder


def test_the_verdict_does_not_depend_on_the_units(tmp_path):
    """Angle and torque times 1e-6, 1e6, 1e80, 1e150: the verdict, the named effect and
    its fitted values are those of the data as they are (the first version: threshold
    inf and "no significant gap" at 1e80)."""
    base = _reflex_trial()
    reports = {}
    for scale in (1.0, 1e-6, 1e6, 1e80, 1e150):
        t = _reflex_trial()
        t.theta, t.tau_h = base.theta * scale, base.tau_h * scale
        folder = _write(tmp_path / f"x{scale:g}", t)
        reports[scale] = diagnose(folder, None, workers=1,
                                  progress=False, config=CFG)
    ref = reports[1.0]
    assert ref.named == ["stretch_reflex"]
    assert np.isfinite(ref.gap["fit_measure"]["threshold"])
    for scale, rep in reports.items():
        assert (rep.verdict, rep.named) == (ref.verdict, ref.named), (scale, rep.summary)
        assert np.isfinite(rep.gap["fit_measure"]["threshold"]), scale
        for key in ("gain", "delay_s", "frequency_hz"):
            assert rep.fitted["stretch_reflex"][key] == pytest.approx(
                ref.fitted["stretch_reflex"][key], rel=1e-3), (scale, key)
        assert rep.arm["K_h"][0][0] == pytest.approx(ref.arm["K_h"][0][0], rel=1e-6)
        rescaled = [c for c in rep.conventions if c["name"] == "units rescaled"]
        assert bool(rescaled) == (scale != 1.0), scale
        assert all(c["note"] for c in rescaled)


def test_an_angle_in_other_units_scales_the_impedance_and_keeps_the_verdict(tmp_path):
    base = _reflex_trial()
    ref = diagnose(_write(tmp_path / "a", base), None, workers=1, progress=False,
                   config=CFG)
    t = _reflex_trial()
    t.theta = base.theta * 1e6          # urad written where rad is declared
    rep = diagnose(_write(tmp_path / "b", t), None, workers=1, progress=False,
                   config=CFG)
    assert (rep.verdict, rep.named) == (ref.verdict, ref.named)
    assert rep.arm["K_h"][0][0] == pytest.approx(ref.arm["K_h"][0][0] * 1e-6, rel=1e-6)
    assert rep.fitted["stretch_reflex"]["gain"] == pytest.approx(
        ref.fitted["stretch_reflex"]["gain"] * 1e-6, rel=1e-3)


def test_numbers_too_small_to_rescale_are_refused_naming_the_file(tmp_path):
    t = _reflex_trial(seconds=12.0)
    t.tau_h = t.tau_h * 1e-300
    folder = _write(tmp_path / "tiny", t)
    with pytest.raises(DiagnosisInputError, match=r"z\.csv: tau_h has an RMS of .*e-30"):
        diagnose(folder, tmp_path / "out", workers=1, progress=False)


@pytest.mark.parametrize("signal, value, unit", [("tau_h", 0.0, "N m"),
                                                 ("theta", 0.1, "rad")])
def test_a_constant_channel_is_refused_naming_the_file_and_channel(tmp_path, signal, value,
                                                                   unit):
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    getattr(t, signal)[:] = value
    folder = _write(tmp_path / "in", t)
    with pytest.raises(DiagnosisInputError) as info:
        diagnose(folder, tmp_path / "out", workers=1, progress=False)
    assert str(info.value) == (f"{folder / 'z.csv'}: {signal}[1] is constant "
                               f"({value:g} {unit}): nothing to diagnose")


@pytest.mark.parametrize("scale", [1.0, 1e9, 1e-9])
def test_a_numerically_constant_angle_is_refused_naming_its_std(tmp_path, scale):
    """An angle of 0.1 rad plus 1e-12 rad per sample (std 5.77e-9 rad, 5.8e-8 of its
    magnitude): at rounding level, no perturbation. The first version fitted it and said
    "convention mismatch: torque sign reversed ... K -21.6"; the check is relative, so the
    same in any units."""
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    n = t.n_samples
    t.theta = (0.1 + 1e-12 * np.arange(n))[:, None] * scale
    t.tau_h = t.tau_h * scale
    folder = _write(tmp_path / "in", t)
    with pytest.raises(DiagnosisInputError) as info:
        diagnose(folder, tmp_path / "out", workers=1, progress=False)
    std = np.std(1e-12 * np.arange(n)) * scale
    msg = str(info.value)
    assert msg.startswith(f"{folder / 'z.csv'}: theta[1] is numerically constant (std ")
    assert float(msg.split("(std ")[1].split(" ")[0]) == pytest.approx(std, rel=1e-2)
    assert "at most 1e-06" in msg and "\n" not in msg
    assert not (tmp_path / "out").exists()


def test_a_small_but_real_variation_is_not_refused():
    """A perturbation of 1e-4 of an angle's offset (2e-5 relative std, above the 1e-6
    threshold) is read."""
    from diagnosis.inputs import check_signals
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    t.theta = 100.0 + t.theta * (1e-2 / np.abs(t.theta).max())
    check_signals(t, "z.csv")


def test_a_plant_fmu_or_rk4_step_with_position_trials_is_refused(tmp_path):
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    folder = _write(tmp_path / "in", t)
    with pytest.raises(DiagnosisInputError, match=r"--fmu plant\.fmu: trials z are position "
                                                  r"experiments.*leave --fmu out"):
        diagnose(folder, tmp_path / "out", workers=1, progress=False, plant="plant.fmu")
    with pytest.raises(DiagnosisInputError, match=r"--rk4-step 1e-05: .*leave --rk4-step"):
        diagnose(folder, tmp_path / "out", workers=1, progress=False, rk4_step=1e-5)
    assert not (tmp_path / "out").exists()
    p = subprocess.run([sys.executable, "-m", "orchestrator", "diagnose", str(folder),
                        "--out", str(tmp_path / "out"), "--fmu", "plant.fmu", "--quiet"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode != 0
    assert "--fmu plant.fmu: trials z are position experiments" in p.stderr
    assert "Traceback" not in p.stderr


def test_an_rk4_step_that_does_not_divide_is_refused_as_not_applicable_first(tmp_path):
    """Position trials with --rk4-step 3e-6 (not a divisor of 1 ms): the first message
    said "does not divide ... use rk4_step 3.003e-06 s", and with that step "leave
    --rk4-step out"; now the first one says the option does not apply."""
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    folder = _write(tmp_path / "in", t)
    with pytest.raises(DiagnosisInputError) as info:
        diagnose(folder, tmp_path / "out", workers=1, progress=False, rk4_step=3e-6)
    assert "--rk4-step 3e-06: trials z are position experiments" in str(info.value)
    assert "leave --rk4-step out" in str(info.value)
    assert "divide" not in str(info.value)


def test_a_plant_experiment_still_refuses_an_rk4_step_that_does_not_divide():
    """The divisibility check where a plant is simulated (the exoskeleton), with the
    trial, its rate and the step that would divide."""
    from types import SimpleNamespace

    from diagnosis.pipeline.conventions import check_plant_options
    trial = SimpleNamespace(name="e1", fs=1000.0)
    r = SimpleNamespace(experiment=SimpleNamespace(uses_plant=True, kind="exoskeleton"),
                        trials=[trial], plant=None, rk4_step=3e-6)
    with pytest.raises(DiagnosisInputError, match=r"e1: fs = 1000 Hz: .*3e-06 s does not "
                                                  r"divide .*use rk4_step 3\.003"):
        check_plant_options(r)
    r.rk4_step = 5e-6
    check_plant_options(r)


def test_tiny_float64_values_are_not_read_as_integers():
    """Angles of 1e-7 rad printed with 17 digits are float64, not "0 decimals" (an
    absolute tolerance of 1e-6 took them for the integer 0)."""
    from diagnosis.storage import detect_storage
    rng = np.random.default_rng(1)
    x = 1e-7 * rng.standard_normal(2000)
    assert detect_storage(x).kind == "float64"
    assert detect_storage(np.round(x * 1e12) / 1e12).describe() == "12 decimals"
    assert detect_storage(1e80 * x).kind == "float64"


def test_a_killed_position_diagnosis_resumes_its_fits(tmp_path, monkeypatch):
    """Interrupted after two effect fits, the re-run reuses them (and fits only the
    others) and writes the report an uninterrupted run writes."""
    import json

    from diagnosis import limbfit as lf
    cfg = DiagnosisConfig(effects=("stretch_reflex", "stiffness_drift", "wobbling_mass",
                                   "channel_delay"))
    folder = _write(tmp_path / "in", _reflex_trial())
    real = lf.fit_effect
    calls = []

    def interrupted(preps, name, *args, **kw):
        if len(calls) == 2:
            raise KeyboardInterrupt  # the user's Ctrl-C (or a kill) during the third fit
        calls.append(name)
        return real(preps, name, *args, **kw)

    monkeypatch.setattr(lf, "fit_effect", interrupted)
    with pytest.raises(KeyboardInterrupt):
        diagnose(folder, tmp_path / "out", workers=1, progress=False, config=cfg)
    assert not (tmp_path / "out" / "report.json").exists()
    done_before = list(calls)
    calls.clear()

    def counted(preps, name, *args, **kw):
        calls.append(name)
        return real(preps, name, *args, **kw)

    monkeypatch.setattr(lf, "fit_effect", counted)
    resumed = diagnose(folder, tmp_path / "out", workers=1, progress=False, config=cfg)
    assert sorted(calls + done_before) == sorted(cfg.effects)   # none fitted twice
    assert resumed.to_dict()["timing"]["resumed_tasks"] >= 2
    fresh = diagnose(folder, tmp_path / "fresh", workers=1, progress=False, config=cfg)

    def stable(path):
        d = json.loads((path / "report.json").read_text())
        for k in ("elapsed_s", "timing"):
            d.pop(k, None)
        return d
    assert stable(tmp_path / "out") == stable(tmp_path / "fresh")
    assert resumed.named == fresh.named == ["stretch_reflex"]
    # the same inputs once more: every fit and the intervals come from the store
    calls.clear()
    again = diagnose(folder, tmp_path / "out", workers=1, progress=False, config=cfg)
    assert calls == [] and again.to_dict()["timing"]["resumed_tasks"] >= len(cfg.effects) + 1
    # other options: another store, every fit run again
    other = DiagnosisConfig(effects=cfg.effects, time_split_fraction=0.55)
    diagnose(folder, tmp_path / "out", workers=1, progress=False, config=other)
    assert sorted(calls) == sorted(cfg.effects)


def test_the_report_compares_like_with_like(tmp_path):
    """A position report: the top-level gaps, the ranking, gap_ranking.png's lines and the
    verdict are in limbfit's measure; the where stage's feature gap is apart under
    ``features`` and labelled so (the first version drew the feature threshold 0.25
    against limbfit's gaps and printed both as "the" nominal gap)."""
    from diagnosis.report import markdown, ranking_lines
    rep = diagnose(_write(tmp_path / "in", _reflex_trial()), tmp_path / "out", workers=1,
                   progress=False, config=CFG)
    g = rep.gap
    assert g["measure"].startswith("limbfit")
    assert g["significance_threshold"] == g["fit_measure"]["threshold"] != 0.25
    assert g["nominal_all"] == g["fit_measure"]["g0_all"]
    assert g["nominal_held_out"] == g["fit_measure"]["g0_held"]
    assert g["features"]["measure"].startswith("features")
    assert g["features"]["significance_threshold"] == 0.25
    assert g["named_all"] is None   # limbfit gives the calibration and held-out parts
    best = rep.ranking[0]
    assert g["named_held_out"] == best["held_out_gap"]
    assert g["named_held_out_reduction"] == pytest.approx(
        1 - best["held_out_gap"] / g["nominal_held_out"])
    lines = ranking_lines(rep)
    assert [v for v, _ in lines] == [g["nominal_held_out"], g["significance_threshold"]]
    assert all("(limbfit)" in label for _, label in lines)
    md = markdown(rep)
    assert "Nominal gap (limbfit), all data" in md and "Feature gap (another measure" in md
    assert "calibration gap (limbfit)" in md and "| group | feature gap |" in md
    assert (tmp_path / "out" / "gap_ranking.png").is_file()


def test_an_exoskeleton_report_keeps_one_measure():
    """Without an experiment's own measure every top-level gap is the feature gap and no
    second measure is given (a run's state built here, no simulation)."""
    from types import SimpleNamespace

    from diagnosis.pipeline.how_far import reduction
    from diagnosis.pipeline.report import FEATURE_MEASURE, gap_block
    r = SimpleNamespace(nominal_all=SimpleNamespace(value=12.0), after=SimpleNamespace(value=0.1),
                        config=DiagnosisConfig(), fit_measure=None, g0_cal=11.0, g0_held=13.0,
                        significant=True)
    chosen = SimpleNamespace(calibration_gap=0.2, held_out_gap=0.3)
    g = gap_block(r, chosen, reduction)
    assert g["measure"] == FEATURE_MEASURE and "features" not in g
    assert (g["nominal_all"], g["significance_threshold"], g["named_all"]) == (12.0, 0.25, 0.1)
    assert g["named_held_out_reduction"] == pytest.approx(1 - 0.3 / 13.0)


def test_the_pipeline_names_a_35_ms_channel_delay(tmp_path):
    """The testers' route (the whole diagnosis on a written trial): a pure 35 ms channel
    delay is named channel_delay, not wobbling_mass."""
    from diagnosis import position_validation as pv
    spec = pv.PositionSetSpec("cd", (("channel_delay", {"delay_s": 0.035}),), n_dof=1,
                              seed=3, duration_s=20.0)
    trial, _ = pv.make_position_trial(spec)
    rep = diagnose(_write(tmp_path / "in", trial), None, workers=1, progress=False,
                   config=CFG)
    assert rep.named == ["channel_delay"], rep.summary
    assert rep.fitted["channel_delay"]["delay_s"] == pytest.approx(0.035, abs=0.001)


def test_a_flagged_best_fit_blocks_the_runner_up_in_position_experiments():
    """Only the best-ranked fit can be named where the experiment says so (the position
    servo, as limbfit's verdict): a runner-up behind a better fit at a bound is not named."""
    from diagnosis.fitting import EffectFit
    from diagnosis.pipeline.verdict import choose
    flagged = EffectFit(("stretch_reflex",), {"stretch_reflex": {"gain": 300.0}}, 0.1, 10,
                        held_out_gap=0.1, objective=0.1)
    flagged.bound_flags = ["gain = 300 at upper search bound"]
    runner = EffectFit(("wobbling_mass",), {"wobbling_mass": {"mass": 0.01,
                                                             "frequency_hz": 8.0}},
                       0.5, 10, held_out_gap=0.05, objective=0.5)
    cfg = DiagnosisConfig()
    assert not flagged.nameable and runner.nameable
    assert choose(True, [flagged, runner], [], 1.0, cfg)[1] == ["wobbling_mass"]
    assert choose(True, [flagged, runner], [], 1.0, cfg, best_only=True)[:2] == \
        ("unexplained", [])


def _lab_noref(tmp_path, scale=1.0, sign=1.0, rows=20000):
    """The example ankle recording without a reference (estimation.examples), its first
    ``rows`` samples, angle and torque times ``scale`` (torque also times ``sign``)."""
    import shutil

    import pandas as pd

    from estimation.examples import write_ankle
    src = tmp_path / "ankle"
    if not (src / "relaxed_noref.csv").exists():
        write_ankle(src)
    d = pd.read_csv(src / "relaxed_noref.csv").iloc[:rows]
    d["theta[1]"] *= scale
    d["tau_h[1]"] *= scale * sign
    folder = tmp_path / f"x{scale:g}_{sign:g}"
    folder.mkdir()
    d.to_csv(folder / "z.csv", index=False)
    shutil.copy(src / "relaxed_noref.json", folder / "z.json")
    return folder


def test_bound_flags_are_in_the_file_units_in_the_verdict_and_the_ranking(tmp_path):
    """x1e9 trials: the verdict quoted the flagged value in the rescaled units
    ("gain = -0.1698 at lower search bound") beside a ranking row of gain=-0.6791; now
    the verdict, the row's parameters and its flags give the file's value, as unscaled."""
    cfg = DiagnosisConfig(effects=("stretch_reflex",))
    reps = {s: diagnose(_lab_noref(tmp_path, s), None, workers=1, progress=False,
                        config=cfg) for s in (1.0, 1e9)}
    ref, big = reps[1.0], reps[1e9]
    assert big.conventions and any(c["name"] == "units rescaled" for c in big.conventions)
    row, brow = ref.ranking[0], big.ranking[0]
    assert row["at_search_bound"], "the example must give a flagged best fit"
    gain = brow["params"]["stretch_reflex"]["gain"]
    assert gain == pytest.approx(row["params"]["stretch_reflex"]["gain"], rel=1e-3)
    shown = f"gain = {gain:.4g}"
    assert all(shown in f for f in brow["at_search_bound"] if "gain" in f)
    assert brow["at_search_bound"] == row["at_search_bound"]
    assert shown in big.summary
    assert big.summary == ref.summary


def test_the_torque_sign_finding_gives_the_stiffness_in_the_file_units(tmp_path):
    """A reversed torque on x1e9 trials: the finding's stiffness is the file's (the
    first version printed the rescaled trials' K)."""
    cfg = DiagnosisConfig(effects=("stretch_reflex",))
    texts = {}
    for s in (1.0, 1e9):
        rep = diagnose(_lab_noref(tmp_path, s, sign=-1.0), None, workers=1,
                       progress=False, config=cfg)
        found = [c for c in rep.conventions if c["name"] == "torque sign reversed"]
        assert found, rep.summary
        texts[s] = found[0]
    k = [float(v) for v in texts[1.0]["evidence"].split("[")[1].split("]")[0].split(",")]
    kb = [float(v) for v in texts[1e9]["evidence"].split("[")[1].split("]")[0].split(",")]
    assert k[0] < 0 and kb == pytest.approx(k, rel=1e-3)


@pytest.mark.parametrize("effects, bad", [(("gravity",), "gravity: not applicable to the "
                                            "position experiment"),
                                           (("servo_bandwidth", "stretch_reflex"),
                                            "servo_bandwidth: needs a recorded theta_ref")])
def test_effects_that_do_not_apply_are_refused_up_front(tmp_path, effects, bad):
    """--effects gravity on position trials said "unexplained: no catalogue effect could
    be fitted"; now refused before any fit, naming it and listing those that apply."""
    from diagnosis import catalogue as cat
    t = position_trial(K=60.0, B=0.8, I=0.012, duration_s=10, record_reference=False,
                       name="z")
    folder = _write(tmp_path / "in", t)
    with pytest.raises(DiagnosisInputError) as info:
        diagnose(folder, tmp_path / "out", workers=1, progress=False,
                 config=DiagnosisConfig(effects=effects))
    msg = str(info.value)
    usable = [n for n in cat.effects_for("position") if n != "servo_bandwidth"]
    assert msg.startswith(f"--effects {','.join(effects)}: {bad}")
    assert f"the effects that apply: {', '.join(usable)} (or leave --effects out" in msg
    assert not (tmp_path / "out").exists()
