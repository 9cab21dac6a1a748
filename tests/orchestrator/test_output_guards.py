"""Outputs of simulate / grid / paper never replace files this project did not write
(a user's trial of the same name, trials in a grid folder without its manifest), and a
path below an existing file is refused up front."""

import json

import pytest

from orchestrator.cli import main

RUN = ["--duration", "0.3", "--dof", "1"]


def _user_trial(stem):
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_name(stem.name + ".csv").write_text("t,theta[1],tau_h[1]\n0,0.1,1\n")
    stem.with_name(stem.name + ".json").write_text('{"fs": 1000}')


def test_simulate_refuses_a_users_trial(reference_fmu, tmp_path, capsys):
    stem = tmp_path / "lab" / "s1"
    _user_trial(stem)
    rc = main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN])
    err = capsys.readouterr().err
    assert rc == 1 and "s1.csv exists and is not a trial this project simulated" in err
    assert "--force" in err and len(err.strip().splitlines()) == 1
    assert (tmp_path / "lab" / "s1.csv").read_text() == "t,theta[1],tau_h[1]\n0,0.1,1\n"
    assert (tmp_path / "lab" / "s1.json").read_text() == '{"fs": 1000}'
    # only the metadata of a user's trial there: refused too
    (tmp_path / "lab" / "s1.csv").unlink()
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN]) == 1
    assert (tmp_path / "lab" / "s1.json").read_text() == '{"fs": 1000}'
    # --force replaces it
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), "--force",
                 *RUN]) == 0
    assert "simulation" in json.loads((tmp_path / "lab" / "s1.json").read_text())


def test_simulate_replaces_its_own_earlier_output(reference_fmu, tmp_path):
    stem = tmp_path / "sim"
    assert main(["simulate", "--out", str(stem), "--fmu", str(reference_fmu), *RUN]) == 0
    assert main(["simulate", "--out", str(stem) + ".csv", "--fmu", str(reference_fmu),
                 "--seed", "3", *RUN]) == 0
    assert json.loads((tmp_path / "sim.json").read_text())["perturbation"]["seed"] == 3


def test_grid_refuses_a_folder_with_trials_but_no_manifest(reference_fmu, tmp_path, capsys):
    out = tmp_path / "g"
    _user_trial(out / "fric0_res0_pert3_dof1")
    rc = main(["grid", str(out), "--workers", "1", "--friction", "0", "--resolution", "0",
               "--perturbation", "3", "--dofs", "1", "--duration", "0.3", "--no-progress",
               "--fmu", str(reference_fmu)])
    err = capsys.readouterr().err
    assert rc == 1 and "holds fric0_res0_pert3_dof1.csv/.json but no grid.json" in err
    assert not (out / "grid.json").exists()


@pytest.mark.parametrize("command", [
    ["simulate", "--out", "{f}/x", *RUN], ["grid", "{f}/g", "--no-progress"],
    ["paper", "--out", "{f}/p", "--quick", "--no-progress"]])
def test_output_below_a_file_is_refused_up_front(tmp_path, capsys, command):
    f = tmp_path / "res.json"
    f.write_text("{}")
    rc = main([c.replace("{f}", str(f)) for c in command])
    err = capsys.readouterr().err
    assert rc == 1 and f"{f} is a file, not a folder" in err and "Errno" not in err


@pytest.fixture(scope="module")
def ankle(tmp_path_factory):
    from estimation.examples import write_ankle

    out = tmp_path_factory.mktemp("ankle")
    write_ankle(out)
    return out


@pytest.mark.parametrize("command", [
    ["estimate", "{src}", "--json", "{f}/x.json"],
    ["figures", "{src}", "--out", "{f}/r"],
    ["diagnose", "{one}", "--out", "{f}/deeper/d"]])
def test_report_output_below_a_file_names_the_file(ankle, tmp_path, capsys, command):
    import shutil

    one = tmp_path / "one"
    one.mkdir()
    for p in ankle.glob("relaxed_noref.*"):
        shutil.copy(p, one)
    f = tmp_path / "A" / "res.json"
    f.parent.mkdir()
    f.write_text("{}")
    args = [c.replace("{src}", str(ankle)).replace("{one}", str(one)).replace("{f}", str(f))
            for c in command]
    rc = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and err, err
    assert f"{args[-1]}: {f} is a file, not a folder" in err[-1] and "Errno" not in err[-1]
    assert f.read_text() == "{}"


def test_check_out_parent_accepts_missing_folders_and_links(tmp_path):
    from trialformat import OutputError, check_out_parent

    check_out_parent(tmp_path / "a" / "b" / "c.json", "--json")  # created later
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    check_out_parent(tmp_path / "link" / "x", "--out")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    with pytest.raises(OutputError, match="dangling is a link to nothing, not a folder"):
        check_out_parent(tmp_path / "dangling" / "x", "--out")
