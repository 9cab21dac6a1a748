"""Issue 22 item 4: ``simulate --out`` writes where it is told, and never over a lab's
trial whose JSON only looks simulated."""

import json

import trialformat as tf
from orchestrator.cli import main

RUN = ["--duration", "0.3", "--dof", "1"]


def test_out_folder_writes_into_the_folder(reference_fmu, tmp_path, capsys):
    out = tmp_path / "S5"
    assert main(["simulate", "--out", str(out) + "/", "--fmu", str(reference_fmu), *RUN]) == 0
    assert (out / "S5.csv").is_file() and (out / "S5.json").is_file()
    assert not (tmp_path / "S5.csv").exists()
    # an existing folder named without the slash: into it too
    assert main(["simulate", "--out", str(out), "--fmu", str(reference_fmu), "--seed", "2",
                 *RUN]) == 0
    assert not (tmp_path / "S5.csv").exists()
    assert json.loads((out / "S5.json").read_text())["perturbation"]["seed"] == 2


def test_out_mat_writes_a_mat(reference_fmu, tmp_path):
    out = tmp_path / "z.mat"
    assert main(["simulate", "--out", str(out), "--fmu", str(reference_fmu), *RUN]) == 0
    assert out.is_file() and not (tmp_path / "z.csv").exists()
    trial = tf.read_trial(out, min_samples=10)
    assert trial.meta["simulation"] and trial.n_dof == 2
    assert main(["simulate", "--out", str(out), "--fmu", str(reference_fmu), *RUN]) == 1


def test_a_lab_csv_beside_a_simulated_looking_json_is_protected(reference_fmu, tmp_path,
                                                                 capsys):
    stem = tmp_path / "lab"
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN]) == 0
    csv = tmp_path / "lab.csv"
    lab = '"t"' + csv.read_text()[1:]  # the lab's own file (a quoted header), same JSON
    assert lab != csv.read_text()
    csv.write_text(lab)
    capsys.readouterr()
    rc = main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN])
    assert rc == 1 and "not a trial this project simulated" in capsys.readouterr().err
    assert csv.read_text() == lab
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), "--force",
                 *RUN]) == 0
    # its own earlier output (sealed) is still replaced without --force
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN]) == 0


def test_grid_refuses_a_level_listed_twice():
    import pytest

    from orchestrator.errors import SetupError
    from orchestrator.grid import grid_tasks
    with pytest.raises(SetupError, match=r"friction levels list a level twice: \[0, 0\]"):
        grid_tasks(friction_levels=(0, 0), resolution_levels=(0,), perturbation_levels=(3,))
    names = [t["name"] for t in grid_tasks()]
    assert len(set(names)) == len(names)
