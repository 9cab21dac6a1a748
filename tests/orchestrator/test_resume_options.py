"""Options checked up front and resumes that would reuse another run's files (issue 16)."""

import json

import pytest

from orchestrator import run_grid
from orchestrator.cli import main as armimp
from orchestrator.effects import parse_effects
from orchestrator.errors import EffectError, SetupError
from trialformat import read_trial

ONE = {"friction_levels": [0], "resolution_levels": [0], "perturbation_levels": [3],
       "dofs": [1]}


@pytest.fixture(scope="module")
def small_grid(reference_fmu, tmp_path_factory):
    out = tmp_path_factory.mktemp("grid")
    m = run_grid(out, workers=1, progress=False, fmu_path=reference_fmu, duration_s=0.5,
                 **ONE)
    assert m["n_done"] == 1
    return out


@pytest.mark.parametrize("changed, flag", [({"duration_s": 9.0}, "--duration 0.5 there, 9.0 now"),
                                           ({"base_seed": 5}, "--seed 0 there, 5 now"),
                                           ({"tuning": "robust"}, "--tuning 'reference' there"),
                                           ({"effects": {"delay": {"samples": 2}}}, "--effects None there")])
def test_resumed_grid_with_other_options_refused_naming_the_option(
        small_grid, reference_fmu, changed, flag):
    before = (small_grid / "fric0_res0_pert3_dof1.csv").read_bytes()
    manifest = (small_grid / "grid.json").read_bytes()
    options = {"duration_s": 0.5, **ONE, **changed}
    with pytest.raises(SetupError, match="holds a grid made with other options") as info:
        run_grid(small_grid, workers=1, progress=False, fmu_path=reference_fmu, **options)
    assert flag in str(info.value)
    assert (small_grid / "fric0_res0_pert3_dof1.csv").read_bytes() == before
    assert (small_grid / "grid.json").read_bytes() == manifest


def test_resumed_grid_with_same_options_skips(small_grid, reference_fmu):
    m = run_grid(small_grid, workers=1, progress=False, fmu_path=reference_fmu,
                 duration_s=0.5, **ONE)
    assert m["n_skipped"] == 1 and m["n_done"] == 0


def test_killed_grid_is_checked_from_its_running_record(tmp_path, reference_fmu):
    # what a grid writes before its first trial: a killed run still records its options
    (tmp_path / "grid.json").write_text(json.dumps({"status": "running",
                                                    "options": {"duration_s": 0.5}}))
    with pytest.raises(SetupError, match="--duration 0.5 there, 50.0 now"):
        run_grid(tmp_path, workers=1, progress=False, fmu_path=reference_fmu, **ONE)


def test_grid_with_missing_or_bad_fmu_refused_before_any_trial(tmp_path):
    with pytest.raises(SetupError, match=r"--fmu .*nope\.fmu: no such file"):
        run_grid(tmp_path / "out", workers=1, progress=False,
                 fmu_path=tmp_path / "nope.fmu", **ONE)
    (tmp_path / "text.fmu").write_text("not a zip")
    with pytest.raises(SetupError, match="not an FMU"):
        run_grid(tmp_path / "out", workers=1, progress=False,
                 fmu_path=tmp_path / "text.fmu", **ONE)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, option, works", [
    (["simulate", "--out", "x", "--duration", "inf"], "--duration", "--duration 50"),
    (["simulate", "--out", "x", "--duration", "-1"], "--duration", "--duration 50"),
    (["simulate", "--out", "x", "--fs", "1e9"], "--fs", "--fs 1000"),
    (["simulate", "--out", "x", "--rk4-step", "0"], "--rk4-step", "--rk4-step 1e-05"),
    (["simulate", "--out", "x", "--comm-step", "nan"], "--comm-step", "--comm-step 0.001"),
    (["grid", "x", "--workers", "0"], "--workers", "--workers 2"),
    (["paper", "--out", "x", "--duration", "1e300"], "--duration", "--duration 50"),
    (["tractability", "--out", "x", "--totals", "0"], "--totals", "--totals 70"),
    (["figures", "a", "--out", "b", "--nfft", "1e8"], "--nfft", "--nfft 8192"),
    (["estimate", "a", "--nperseg", "1.5"], "--nperseg", "--nperseg 8192"),
    (["diagnose", "a", "--out", "b", "--rk4-step=-1e-5"], "--rk4-step", "--rk4-step 1e-05"),
    (["validate-diagnosis", "--out", "b", "--duration", "inf"], "--duration", "--duration 12"),
])
def test_cli_values_refused_at_parse_time_naming_option_and_a_value_that_works(
        argv, option, works, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        armimp(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"argument {option}" in err and f"(e.g. {works})" in err
    assert list(tmp_path.iterdir()) == []


def test_simulate_longer_than_the_sample_limit_refused(capsys, tmp_path):
    assert armimp(["simulate", "--out", str(tmp_path / "x"), "--fs", "100000",
                   "--duration", "1000"]) == 1
    err = capsys.readouterr().err
    assert "above the limit of 10000000" in err and "--duration <= 100" in err
    assert list(tmp_path.iterdir()) == []


def test_simulate_dotted_out_keeps_its_name(tmp_path, capsys, reference_fmu):
    assert armimp(["simulate", "--out", str(tmp_path / "level_0.5"), "--duration", "0.2",
                   "--fmu", str(reference_fmu)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["level_0.5.csv", "level_0.5.json"]
    assert read_trial(tmp_path / "level_0.5", min_samples=0).name == "level_0.5"


def test_effect_delay_of_1e8_samples_refused_up_front():
    with pytest.raises(EffectError, match="'samples' must be <= 100000, got 100000000"):
        parse_effects({"delay": {"samples": 100_000_000}}, 2)


def test_tractability_with_zero_total_refused_before_any_work(tmp_path):
    from orchestrator.tractability import run_tractability
    with pytest.raises(SetupError, match=r"finite and > 0 \[s\], got \[0\.0\]"):
        run_tractability(tmp_path / "t", ns=(2,), totals_s=(0.0,), progress=False)
    assert not (tmp_path / "t").exists()


def test_resumed_grid_with_other_plant_parameters_refused(small_grid, reference_fmu):
    manifest = (small_grid / "grid.json").read_bytes()
    with pytest.raises(SetupError, match=r"--plant-parameter None there, "
                                         r"\{'motor_enable': 0\.0\} now"):
        run_grid(small_grid, workers=1, progress=False, fmu_path=reference_fmu,
                 duration_s=0.5, plant_parameters={"motor_enable": 0.0}, **ONE)
    assert (small_grid / "grid.json").read_bytes() == manifest
    # an empty set is no parameter given: resumes
    m = run_grid(small_grid, workers=1, progress=False, fmu_path=reference_fmu,
                 duration_s=0.5, plant_parameters={}, **ONE)
    assert m["n_skipped"] == 1


@pytest.mark.parametrize("recorded, now, message", [
    ({}, "modelica", "--plant 'c' there, 'modelica' now"),  # before the key: the C plant
    ({"plant": "modelica"}, "c", "--plant 'modelica' there, 'c' now")])
def test_resumed_grid_with_other_builtin_plant_refused(tmp_path, monkeypatch, recorded, now,
                                                        message):
    (tmp_path / "grid.json").write_text(json.dumps(
        {"status": "running", "options": {"duration_s": 0.5, **recorded}}))
    monkeypatch.setenv("ARMEXO_PLANT", now)  # what armimp --plant sets
    with pytest.raises(SetupError, match=message):
        run_grid(tmp_path, workers=1, progress=False, duration_s=0.5, **ONE)


def test_resumed_grid_with_an_fmu_of_other_content_refused(tmp_path, reference_fmu,
                                                           linear_fmu):
    import shutil

    plant = tmp_path / "plant.fmu"
    shutil.copyfile(reference_fmu, plant)
    out = tmp_path / "g"
    assert run_grid(out, workers=1, progress=False, fmu_path=plant, duration_s=0.5,
                    **ONE)["n_done"] == 1
    shutil.copyfile(linear_fmu, plant)  # same name, another plant
    with pytest.raises(SetupError, match=r"--fmu 'plant.fmu' has other content"):
        run_grid(out, workers=1, progress=False, fmu_path=plant, duration_s=0.5, **ONE)


def test_cli_grid_resumed_with_plant_parameter_refused(small_grid, reference_fmu, capsys):
    rc = armimp(["grid", str(small_grid), "--workers", "1", "--friction", "0",
                 "--resolution", "0", "--perturbation", "3", "--dofs", "1", "--duration",
                 "0.5", "--fmu", str(reference_fmu), "--plant-parameter", "motor_enable=1",
                 "--no-progress"])
    assert rc == 1 and "--plant-parameter None there" in capsys.readouterr().err
