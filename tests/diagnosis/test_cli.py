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


def test_parallel_and_plant_step_options_reach_the_diagnosis():
    args = cli.build_parser().parse_args(
        ["diagnose", "f", "--out", "r", "--workers", "1", "--scheduler", "tcp://h:8786",
         "--rk4-step", "5e-6"])
    assert (args.workers, args.scheduler, args.rk4_step) == (1, "tcp://h:8786", 5e-6)
    args = cli.build_parser().parse_args(["simulate", "--out", "x", "--fs", "2048",
                                          "--rk4-step", "4.8828125e-06"])
    assert (args.fs, args.rk4_step) == (2048.0, 4.8828125e-06)


def test_a_plant_step_that_does_not_divide_the_period_is_refused_up_front(tmp_path, capsys):
    code = cli.main(["simulate", "--out", str(tmp_path / "x"), "--fs", "1024",
                     "--rk4-step", "1e-5", "--duration", "1"])
    assert code == 1
    err = capsys.readouterr().err
    assert "1e-05" in err and "0.0009765625" in err
