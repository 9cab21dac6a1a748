"""Bad input, the blind reading of trials, the split rule and the catalogue (no simulator)."""

import json

import numpy as np
import pytest

import trialformat as tf
from diagnosis import CATALOGUE, DiagnosisConfig, DiagnosisInputError, diagnose, split_units
from diagnosis.catalogue import expand_effect, relative_parameter_error
from diagnosis.inputs import load_trials


def _write(folder, make, name, **kw):
    trial = make(name=name, **kw)
    tf.write_trial(folder / name, trial)
    return trial


def test_folder_without_trials_is_refused(tmp_path):
    with pytest.raises(DiagnosisInputError, match="no trial"):
        diagnose(tmp_path, progress=False)


def test_disagreeing_metadata_names_both_files(tmp_path, make_linear_trial):
    _write(tmp_path, make_linear_trial, "a")
    trial = make_linear_trial(name="b", perturbed_dof=2)
    trial.meta["friction"] = tf.reference.friction_level(2)
    tf.write_trial(tmp_path / "b", trial)
    with pytest.raises(DiagnosisInputError, match=r"'b'.*friction.*'a'"):
        load_trials(tmp_path)


@pytest.mark.parametrize("key, value", [("fs", 500.0), ("sensors", {"encoder_resolution_deg":
                                        0.1, "torque_resolution_nm": 0.0}),
                                        ("controller", tf.reference.controller("robust"))])
def test_each_declared_key_must_agree(tmp_path, make_linear_trial, key, value):
    _write(tmp_path, make_linear_trial, "a")
    trial = make_linear_trial(name="b")
    trial.meta[key] = value
    if key == "fs":
        trial.t = np.arange(trial.n_samples) / value
    tf.write_trial(tmp_path / "b", trial)
    with pytest.raises(DiagnosisInputError, match=key):
        load_trials(tmp_path)


def test_too_short_trial_names_the_file(tmp_path, make_linear_trial):
    _write(tmp_path, make_linear_trial, "short", n_samples=5000)
    with pytest.raises(DiagnosisInputError, match="short.csv"):
        diagnose(tmp_path, progress=False)


def test_lone_trial_too_short_for_a_time_split(make_linear_trial):
    trials = [make_linear_trial(name="a", n_samples=6000),
              make_linear_trial(name="b", n_samples=6000, perturbed_dof=2)]
    with pytest.raises(DiagnosisInputError, match="'a'"):
        split_units(trials, DiagnosisConfig())


def test_truth_files_and_simulation_key_are_never_read(tmp_path, make_linear_trial):
    trial = make_linear_trial(name="a")
    trial.meta["simulation"] = {"effects": {"gravity": {"tilt_deg": 5}}}
    tf.write_trial(tmp_path / "a", trial)
    (tmp_path / "a.truth.json").write_text("{ not json, must never be parsed")
    (tmp_path / "x.truth.csv").write_text("garbage")
    loaded = load_trials(tmp_path)
    assert [t.name for t in loaded] == ["a"]
    assert "simulation" not in loaded[0].meta


def test_split_rules(make_linear_trial):
    one_each = [make_linear_trial(name="a"), make_linear_trial(name="b", perturbed_dof=2)]
    cal, held, rule = split_units(one_each, DiagnosisConfig())
    assert rule == "time"
    assert all(c.stop == h.start for c, h in zip(cal, held))
    four = [make_linear_trial(name=f"t{k}{s}", seed=s, perturbed_dof=k)
            for k in (1, 2) for s in (1, 2)]
    cal, held, rule = split_units(four, DiagnosisConfig())
    assert rule == "trials"
    assert {u.trial.name for u in cal}.isdisjoint({u.trial.name for u in held})
    assert sorted(u.trial.perturbed_dof for u in held) == [1, 2]


def test_catalogue_agrees_with_the_orchestrator():
    """Every effect and every expanded parameter exists in the simulator's catalogue."""
    orch = pytest.importorskip("orchestrator.effects")
    from diagnosis.catalogue import effects_for
    assert set(effects_for("exoskeleton")) == set(orch.CATALOGUE)
    rng = np.random.default_rng(0)
    for name in effects_for("exoskeleton"):
        effect = CATALOGUE[name]
        params = expand_effect(name, effect.draw(rng), 2)
        orch.parse_effects({name: params}, 2)  # raises on a bad name or value


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_draws_lie_in_the_realistic_ranges(name):
    effect = CATALOGUE[name]
    rng = np.random.default_rng(1)
    for _ in range(20):
        drawn = effect.draw(rng)
        for p in effect.parameters:
            lo, hi = p.realistic
            v = drawn[p.name]
            if effect.sign_choice:
                v = p.off + abs(v - p.off)
            assert lo <= v <= hi
            assert p.bounds[0] <= drawn[p.name] <= p.bounds[1]


def test_parameter_error_is_relative_to_the_effect_size():
    err = relative_parameter_error("inertia_mismatch", {"scale": 1.22}, {"scale": 1.2})
    assert err["scale"] == pytest.approx(0.1)


def test_missing_folder_is_refused_with_its_name(tmp_path):
    with pytest.raises(DiagnosisInputError, match="nowhere"):
        diagnose(tmp_path / "nowhere", progress=False)


def test_data_file_without_metadata_names_the_file(tmp_path, make_linear_trial):
    _write(tmp_path, make_linear_trial, "a")
    _write(tmp_path, make_linear_trial, "b", perturbed_dof=2)
    (tmp_path / "b.json").unlink()
    with pytest.raises(DiagnosisInputError, match=r"b\.json"):
        diagnose(tmp_path, progress=False)


def test_disagreeing_robot_is_refused_before_any_simulation(tmp_path, make_linear_trial):
    _write(tmp_path, make_linear_trial, "a")
    trial = make_linear_trial(name="b", perturbed_dof=2)
    trial.meta["robot"] = dict(trial.meta["robot"], m1=trial.meta["robot"]["m1"] * 1.1)
    tf.write_trial(tmp_path / "b", trial)
    with pytest.raises(DiagnosisInputError, match=r"'b'.*robot"):
        diagnose(tmp_path, progress=False)
