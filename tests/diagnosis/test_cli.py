"""The diagnosis subcommands of ``python -m orchestrator``."""

import pytest

cli = pytest.importorskip("orchestrator.cli")


def test_subcommands_are_registered():
    parser = cli.build_parser()
    args = parser.parse_args(["diagnose", "somewhere", "--out", "rep", "--effects", "gravity"])
    assert args.command == "diagnose" and args.effects == "gravity"
    args = parser.parse_args(["validate-diagnosis", "--out", "v", "--per-effect", "1"])
    assert args.per_effect == 1


def test_diagnose_empty_folder_fails_with_a_message(tmp_path, capsys):
    assert cli.main(["diagnose", str(tmp_path), "--out", str(tmp_path / "r"), "--quiet"]) == 1
    assert "no trial" in capsys.readouterr().err


def test_unknown_effect_is_refused(tmp_path, capsys):
    assert cli.main(["diagnose", str(tmp_path), "--out", str(tmp_path / "r"),
                     "--effects", "wind"]) == 1
    assert "wind" in capsys.readouterr().err
