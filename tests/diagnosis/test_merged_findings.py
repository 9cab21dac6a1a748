"""A note repeated over the trials is said once in report.md and the summary, with its
count (README: "the same reader note on many files is said once with the count")."""

from types import SimpleNamespace

from diagnosis.conventions import Finding, merged_texts
from diagnosis.pipeline import where


def _declared(n):
    return [Finding("declared: torque_sign -1", f"trial{i:02d}", "tau_h negated by the reader")
            for i in range(n)]


def test_a_note_on_ten_trials_is_said_once_with_the_count():
    out = merged_texts(_declared(10) + [Finding("t rounded", "t, trial00", "1e-3 s")])
    assert out == ["declared: torque_sign -1 (10 trials: trial00, trial01, trial02, ...): "
                   "tau_h negated by the reader; corrected", "t rounded (t, trial00): 1e-3 s; "
                   "corrected"], out


def test_an_identical_note_repeated_is_said_once_with_the_count():
    same = [Finding("torque sign reversed", "tau_h, all trials", "K -80") for _ in range(10)]
    assert merged_texts(same) == ["torque sign reversed (tau_h, all trials): K -80; "
                                  "corrected (x 10)"]


def test_the_report_conventions_merge_the_notes(monkeypatch):
    monkeypatch.setattr(where, "grids", lambda *a: None)
    monkeypatch.setattr(where, "where_breakdown", lambda *a: None)
    r = SimpleNamespace(findings=_declared(10), trials=[], experiment=None, nominal_all=None)
    where.run(r)
    assert len(r.where["conventions"]) == 1 and "10 trials" in r.where["conventions"][0]
