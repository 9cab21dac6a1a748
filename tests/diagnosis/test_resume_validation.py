"""A resumed ``validate-diagnosis`` never reuses the sets or rows of a run made with other
options, and failed sets make it exit non-zero (issue 16)."""

import json

import pytest

from diagnosis import validation as val
from diagnosis.errors import DiagnosisInputError
from orchestrator.cli import main as armimp


def test_set_made_with_another_spec_is_refused_naming_the_field(tmp_path):
    old = val.SetSpec("nominal-0", seeds=(17,), duration_s=12.0)
    (tmp_path / "nominal-0").mkdir()
    (tmp_path / "nominal-0" / val.SET_FILE).write_text(json.dumps(val.spec_record(old)))
    val.check_spec(tmp_path / "nominal-0" / val.SET_FILE, old)  # same spec: fine
    new = val.SetSpec("nominal-0", seeds=(999,), duration_s=20.0)
    with pytest.raises(DiagnosisInputError, match=r"duration_s: 12\.0 there, 20\.0 now.*"
                                                  r"seeds: \[17\] there, \[999\] now") as info:
        val.make_set(new, tmp_path)
    assert "nominal-0" in str(info.value)
    assert sorted(p.name for p in (tmp_path / "nominal-0").iterdir()) == [val.SET_FILE]


def test_run_validation_refuses_rows_of_another_run_before_any_work(tmp_path):
    old = val.SetSpec("nominal-0", seeds=(17,))
    row = tmp_path / "reports" / "nominal-0" / "score_row.json"
    row.parent.mkdir(parents=True)
    row.write_text(json.dumps({"set": "nominal-0", "spec": val.spec_record(old)}))
    with pytest.raises(DiagnosisInputError, match=r"seeds: \[17\] there, \[18\] now"):
        val.run_validation([val.SetSpec("nominal-0", seeds=(18,))], tmp_path, progress=False)
    row.write_text(json.dumps({"set": "nominal-0"}))  # an older run's row
    with pytest.raises(DiagnosisInputError, match="records no spec"):
        val.run_validation([old], tmp_path, progress=False)
    assert not (tmp_path / "score.json").exists() and not (tmp_path / "sets").exists()


def test_cli_resume_with_other_options_names_them(tmp_path, capsys):
    (tmp_path / "validation.json").write_text(json.dumps({"options": {
        "--per-effect": 2, "--nominal": 4, "--pairs": 2, "--outside": 1,
        "--duration": 12.0, "--seed": 2024}}))
    assert armimp(["validate-diagnosis", "--out", str(tmp_path), "--seed", "999",
                   "--duration", "20", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "--duration 12.0 there, 20.0 now" in err and "--seed 2024 there, 999 now" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["validation.json"]


def test_cli_exits_non_zero_when_a_set_failed(tmp_path, capsys, monkeypatch):
    def fake(specs, out, **kw):
        return {"summary": {"failed_sets": [{"set": specs[0].name, "error": "boom"}]},
                "table_markdown": "(table)"}
    monkeypatch.setattr(val, "run_validation", fake)
    assert armimp(["validate-diagnosis", "--out", str(tmp_path), "--quiet"]) == 1
    assert "1 of " in capsys.readouterr().out
