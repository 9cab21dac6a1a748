"""Issue 22 (a lab's whole session): units of theta_ref, one grouping rule, one name per
output, in the diagnosis."""

import dataclasses

import numpy as np
import pytest

from diagnosis.conventions import check_angles
from estimation.synthetic import position_trial


def _ref_trial(**kw):
    return position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=3, **kw)


def test_theta_ref_in_degrees_is_converted_with_theta():
    t = _ref_trial()
    deg = dataclasses.replace(t, theta=np.degrees(t.theta), theta_ref=np.degrees(t.theta_ref))
    out, found = check_angles([deg])
    assert "angles in degrees" in [f.name for f in found]
    np.testing.assert_allclose(out[0].theta_ref, t.theta_ref, atol=1e-12)
    np.testing.assert_allclose(out[0].theta, t.theta, atol=1e-12)


def test_theta_ref_in_degrees_beside_theta_in_radians_is_noticed():
    t = _ref_trial()
    deg = dataclasses.replace(t, theta_ref=np.degrees(t.theta_ref))
    out, found = check_angles([deg])
    names = [f.name for f in found]
    assert "theta_ref in degrees" in names, names
    np.testing.assert_allclose(out[0].theta_ref, t.theta_ref, atol=1e-12)
    np.testing.assert_allclose(out[0].theta, t.theta, atol=1e-12)


def test_diagnose_reader_says_a_repeated_note_once(tmp_path):
    """200 files lacking one key gave 200 identical notes; now one, with the count."""
    import json

    import pandas as pd

    import trialformat as tf
    from diagnosis.inputs import load_trials
    rng = np.random.default_rng(3)
    n = 9000
    for i in range(3):
        cols = {"t": np.arange(n) / 1000.0, "theta[1]": rng.standard_normal(n),
                "tau_h[1]": rng.standard_normal(n)}
        pd.DataFrame(cols).to_csv(tmp_path / f"r{i}.csv", index=False)
        meta = tf.default_metadata(1)
        meta.update(perturbation={"kind": "position"})
        meta.pop("friction")
        (tmp_path / f"r{i}.json").write_text(json.dumps(meta))
    with pytest.warns(UserWarning) as record:
        load_trials(tmp_path)
    said = [str(w.message) for w in record if "metadata keys absent" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("3 files (r0.csv, r1.csv, r2.csv): ")


def test_a_held_joints_absent_reference_is_not_refused_as_constant():
    """Two-joint position trials with theta_ref only for the perturbed joint (as
    log-format.md describes) were refused: "theta_ref[2] is constant (0 rad)"."""
    import trialformat as tf
    from diagnosis.errors import DiagnosisInputError
    from diagnosis.inputs import check_signals
    rng = np.random.default_rng(0)
    n = 2000
    meta = tf.default_metadata(2)
    meta.update(perturbation={"kind": "position"}, perturbed_dof=1)
    ref = np.column_stack([rng.standard_normal(n), np.zeros(n)])
    trial = tf.Trial(meta=meta, name="p1", t=np.arange(n) / 1000.0,
                     theta=rng.standard_normal((n, 2)), tau_h=rng.standard_normal((n, 2)),
                     theta_ref=ref)
    check_signals(trial, "p1.csv")
    trial.theta_ref = ref[:, ::-1].copy()  # the perturbed joint's reference constant
    with pytest.raises(DiagnosisInputError, match=r"theta_ref\[1\] is constant"):
        check_signals(trial, "p1.csv")


def test_plant_choice_on_position_trials_is_said_not_used(monkeypatch):
    """--plant modelica / ARMEXO_PLANT=modelica with position trials was ignored silently."""
    from types import SimpleNamespace

    from diagnosis.pipeline.conventions import check_plant_options
    from diagnosis.pipeline.report import simulated_by
    r = SimpleNamespace(experiment=SimpleNamespace(uses_plant=False, kind="position"),
                        trials=[SimpleNamespace(name="relaxed_1")], plant=None, rk4_step=None)
    monkeypatch.delenv("ARMEXO_PLANT", raising=False)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_plant_options(r)  # nothing chosen: nothing said
    monkeypatch.setenv("ARMEXO_PLANT", "modelica")
    with pytest.warns(UserWarning, match=r"ARMEXO_PLANT = modelica is not used: trials "
                      r"relaxed_1 are position experiments, re-simulated by the limb model"):
        check_plant_options(r)
    assert simulated_by(r).startswith("diagnosis.limb")

def _ankle_session():
    """As ``python -m estimation.examples ankle``: two labels, one unlabelled recording."""
    trials = [position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=s, condition=c,
                             name=f"{c}_{s}")
              for c, s in (("relaxed", 1), ("relaxed", 2), ("co-contracted", 3))]
    trials.append(position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=4,
                                 record_reference=False, name="relaxed_noref"))
    return trials


def test_diagnose_groups_the_readme_example_like_estimate():
    from diagnosis.inputs import split_conditions
    from estimation.lab import estimation_units
    trials = _ankle_session()
    groups = split_conditions(trials)  # was refused: relaxed_noref has no label
    assert {k: [t.name for t in v] for k, v in groups.items()} == {
        "relaxed": ["relaxed_1", "relaxed_2"], "co-contracted": ["co-contracted_3"],
        "relaxed_noref": ["relaxed_noref"]}
    units = {u.label: [t.name for t in u.trials] for u in estimation_units(trials)}
    assert units == {k: [t.name for t in v] for k, v in groups.items()}


def test_unlabelled_recordings_of_two_limbs_are_not_pooled_by_diagnose():
    from diagnosis.inputs import split_conditions
    a = position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=1, name="a")
    b = position_trial(K=150.0, B=1.2, I=0.012, duration_s=10, seed=2, name="b")
    groups = split_conditions([a, b])
    assert [[t.name for t in g] for g in groups.values()] == [["a"], ["b"]]


def test_a_condition_that_is_not_a_string_is_refused_by_name():
    import pytest

    from diagnosis.errors import DiagnosisInputError
    from diagnosis.inputs import split_conditions
    t = _ref_trial(name="x")
    t.meta["condition"] = ["a"]
    with pytest.raises(DiagnosisInputError, match=r"x: key 'condition' must be a string.*\[\"a\"\]"):
        split_conditions([t])


def test_colliding_labels_get_unique_report_folders():
    from diagnosis.core import _safe
    from estimation.grouping import unique_file_names
    from estimation.labreport import safe_name
    labels = ["day1/left", "day1_left", "Sübject", "Söbject"]
    for safe, renamed in ((_safe, 2), (safe_name, 2)):
        names, notes = unique_file_names(labels, safe)
        assert len({n.lower() for n in names}) == 4, names
        assert len(notes) == renamed and "day1_left_2" in notes[0]


def test_figures_and_diagnose_name_a_label_alike():
    """"PF 10%" was frf_PF_10 from figures but folder PF_10_ from diagnose."""
    from diagnosis.core import _safe
    from estimation.labreport import safe_name
    for label in ("PF 10%", "co-contract", "day1/left", "Sübject", "a  b"):
        assert _safe(label) == safe_name(label), label
    assert _safe("PF 10%") == "PF_10"


def test_diagnose_refuses_a_read_only_out_before_any_work(tmp_path):
    read_only = tmp_path / "archive"
    read_only.mkdir()
    read_only.chmod(0o555)
    from diagnosis.errors import DiagnosisInputError
    from diagnosis.pipeline.report import check_out_dir
    with pytest.raises(DiagnosisInputError, match="read-only"):
        check_out_dir(read_only, tmp_path / "trials")
    assert list(read_only.iterdir()) == []
    read_only.chmod(0o755)
