"""The command line (argparse only; the work is in library functions)."""

import json
import subprocess
import sys

import pytest

from orchestrator.cli import build_parser, main
from trialformat import read_trial


def test_simulate_writes_a_trial(reference_fmu, tmp_path, capsys):
    stem = tmp_path / "one"
    rc = main(["simulate", "--out", str(stem), "--friction", "2", "--resolution", "1",
               "--perturbation", "2", "--dof", "2", "--seed", "5", "--duration", "8.2",
               "--effects", '{"sensor_noise": {"tau_noise_std_nm": 0.01}}',
               "--fmu", str(reference_fmu)])
    assert rc == 0 and "wrote" in capsys.readouterr().out
    trial = read_trial(stem.with_suffix(".csv"))
    assert trial.perturbed_dof == 2 and trial.meta["perturbation"]["seed"] == 5
    assert trial.meta["simulation"]["effects"]["sensor_noise"]["tau_noise_std_nm"] == [0.01,
                                                                                        0.01]


def test_simulate_all_joints_and_no_tde(reference_fmu, tmp_path):
    stem = tmp_path / "all"
    assert main(["simulate", "--out", str(stem), "--dof", "all", "--duration", "8.2",
                 "--no-tde", "--fmu", str(reference_fmu)]) == 0
    meta = json.loads(stem.with_suffix(".json").read_text())
    assert meta["perturbed_dof"] is None
    assert meta["controller"]["time_delay_estimation"] is False


@pytest.mark.parametrize("args,message", [
    (["--effects", "{bad json"], "--effects is not valid JSON"),
    (["--effects", '{"wind": {}}'], "unknown effect 'wind'"),
    (["--dof", "x"], "--dof must be an integer"),
    (["--friction", "7"], "friction level")])
def test_simulate_bad_input_exits_1_with_message(reference_fmu, tmp_path, capsys, args,
                                                  message):
    rc = main(["simulate", "--out", str(tmp_path / "x"), "--duration", "0.1",
               "--fmu", str(reference_fmu)] + args)
    assert rc == 1 and message in capsys.readouterr().err


def test_info_prints_contract_and_parameters(reference_fmu, tmp_path, capsys):
    assert main(["info", str(reference_fmu)]) == 0
    out = capsys.readouterr().out
    assert "contract: OK, 2 joints" in out and "friction.Fc[1] = 0.0" in out
    assert "FMI 2.0 Co-Simulation" in out
    assert main(["info", str(reference_fmu), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["n_dof"] == 2
    fake = tmp_path / "fake.fmu"
    fake.write_text("text")
    assert main(["info", str(fake)]) == 1
    assert "not an FMU" in capsys.readouterr().err


def test_grid_command(reference_fmu, tmp_path, capsys):
    rc = main(["grid", str(tmp_path), "--workers", "1", "--friction", "1", "--resolution",
               "0", "--perturbation", "3", "--dofs", "1", "--duration", "8.2",
               "--fmu", str(reference_fmu), "--no-progress"])
    assert rc == 0 and "1 done" in capsys.readouterr().out
    assert (tmp_path / "fric1_res0_pert3_dof1.csv").is_file()


def test_subcommands_of_other_packages_registered():
    names = build_parser()._subparsers._group_actions[0].choices
    assert {"simulate", "grid", "info"} <= set(names)
    try:
        import estimation.cli  # noqa: F401
    except ImportError:
        return
    assert "estimate" in names


def test_module_entry_point():
    out = subprocess.run([sys.executable, "-m", "orchestrator", "--help"],
                         capture_output=True, text=True, check=True).stdout
    assert "simulate" in out and "grid" in out and "info" in out
