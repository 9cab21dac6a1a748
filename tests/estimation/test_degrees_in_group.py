"""One recording in degrees, undeclared, inside a labelled group in radians (lab session
tester): it is named and refused alone before pooling, the others estimated; the unit
advice names every angle channel (theta and theta_ref); no band advice on top of it."""

import numpy as np

import trialformat as tf
from estimation import lab
from estimation.cli import main
from estimation.synthetic import position_trial


def _deg(trial):
    return tf.Trial(**{**trial.__dict__, "theta": np.degrees(trial.theta),
                       "theta_ref": np.degrees(trial.theta_ref)})


def test_a_recording_in_degrees_is_refused_alone_the_group_estimated(tmp_path, capsys):
    folder = tmp_path / "s"
    for i in range(4):
        t = position_trial(K=80.0, B=1.2, I=0.012, duration_s=30, seed=i, name=f"r{i}",
                           condition="relaxed")
        tf.write_trial(folder / f"r{i}", _deg(t) if i == 3 else t)
    assert main(["estimate", str(folder)]) == 1
    cap = capsys.readouterr()
    assert ("error: r3: its angles look like degrees (" in cap.err
            and "the other recordings of 'relaxed' are in radians; declare \"units\": "
                "{\"theta\": \"deg\", \"theta_ref\": \"deg\"} in r3.json" in cap.err), cap.err
    k = float(cap.out.split("K=")[1].split("±")[0])
    assert abs(k - 80) < 4, cap.out  # the three in radians, not a pooled 1.48
    assert "suggested band" not in cap.out and "angles in degrees" not in cap.out
    assert "relaxed (label, 3 trials)" in cap.out and "trials=r0, r1, r2 " in cap.out


def test_unit_advice_names_theta_ref_and_no_band_advice(tmp_path):
    t = _deg(position_trial(K=80.0, B=1.2, I=0.012, duration_s=30, seed=0, name="deg"))
    r = lab.analyse(lab.Unit("deg", [t], "one"))
    said = [w for w in r.warnings if w.startswith("angles in degrees?")]
    assert said and all('{"theta": "deg", "theta_ref": "deg"}' in w and
                        "theta_ref[1] (deg)" in w for w in said), said
    assert not any(w.startswith(("suggested band", "no band tried")) for w in r.warnings)


def test_no_band_advice_on_top_of_the_degree_suspicion():
    """The pooled set (analyse called directly): 'suggested band' led to a loop."""
    ts = [position_trial(K=80.0, B=1.2, I=0.012, duration_s=30, seed=i, name=f"r{i}",
                         condition="relaxed") for i in range(4)]
    ts[3] = _deg(ts[3])
    r = lab.analyse(lab.Unit("relaxed", ts, "label"))
    assert any(w.startswith("angles in degrees?") for w in r.warnings), r.warnings
    assert not any(w.startswith(("suggested band", "no band tried")) for w in r.warnings)
