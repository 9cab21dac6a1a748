"""Hostile or broken FMU archives and plants at the edges of the contract (issue 16).

Every input is built here: archives rewritten from the hand-written swap plant
(tests/orchestrator/swap_plants), its C variants, and the project's FMI 3.0 build with a
clock added to its model description. Each refusal must name the FMU file, and no
extracted folder may be left behind.
"""

import os
import re
import tempfile
import warnings
import zipfile

import numpy as np
import pytest
from swap_plants import have_compiler

from orchestrator import (ContractError, FMUCallError, Plant, PlantFileError, PlantWarning,
                          Setup, run_grid, simulate_trial)
from orchestrator import plant as plant_module
from orchestrator.cli import main as cli_main
from orchestrator.errors import DivergenceError, ParameterError

pytestmark = pytest.mark.skipif(not have_compiler(), reason="no C compiler")


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """The system temporary folder of this test: extracted FMUs land (and must not stay)
    here."""
    tmp = tmp_path / "systmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    return tmp


def _leftovers(tmp):
    return [p.name for p in tmp.iterdir() if p.name.startswith("armimp-fmu-")]


def _rewrite(src, dest, *, drop=(), add=(), edit=None):
    """Copy the archive ``src`` to ``dest`` without the entries ``drop``, with ``add`` =
    [(ZipInfo or name, bytes)], and ``edit(name, data) -> data``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            if info.filename in drop:
                continue
            data = zin.read(info)
            if edit is not None:
                data = edit(info.filename, data)
            zout.writestr(info, data)
        for name, data in add:
            zout.writestr(name, data)
    return dest


def _symlink_info(name, target="/etc/passwd"):
    info = zipfile.ZipInfo(name)
    info.create_system = 3
    info.external_attr = (0o120777 << 16)
    return info, target.encode()


# ------------------------------------------------------------------------ archives
@pytest.mark.parametrize("entry, why", [
    ("../evil.txt", "holds '..'"),
    ("resources/../../evil.txt", "holds '..'"),
    ("/tmp/evil.txt", "absolute path"),
    ("C:/evil.txt", "absolute path"),
    ("resources\\evil.txt", "backslash"),
    ("symlink", "symbolic link"),
])
def test_hostile_entry_names_are_refused_naming_fmu_and_entry(swap, tmp_path, private_tmp,
                                                                entry, why):
    if entry == "symlink":
        add = [_symlink_info("resources/link")]
        entry = "resources/link"
    else:
        add = [(entry, b"x")]
    fmu = _rewrite(swap("nominal"), tmp_path / "hostile.fmu", add=add)
    with pytest.raises(PlantFileError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("hostile.fmu: archive entry ") and repr(entry) in text, text
    assert why in text and "\n" not in text
    assert _leftovers(private_tmp) == []
    assert not (tmp_path / "evil.txt").exists()


def test_zip_bomb_refused_by_declared_size(swap, tmp_path, private_tmp, monkeypatch):
    """8 MiB of zeros (a few KB compressed) against a 4 MiB limit; the real limit is 1 GiB."""
    monkeypatch.setattr(plant_module, "MAX_FMU_BYTES", 4 << 20)
    fmu = _rewrite(swap("nominal"), tmp_path / "bomb.fmu",
                   add=[("resources/zeros.bin", bytes(8 << 20))])
    assert fmu.stat().st_size < 100_000
    with pytest.raises(PlantFileError, match=r"^bomb\.fmu: the FMU archive unpacks to 8 MiB, "
                                             r"more than the 4 MiB"):
        Plant(fmu)
    assert _leftovers(private_tmp) == []


def test_zip_bomb_that_lies_about_its_size_is_refused(swap, tmp_path, private_tmp, monkeypatch):
    """The archive's directory says 0 bytes for an 8 MiB entry: refused naming the FMU (the
    bytes read are limited to the declared size and counted), the partial extraction
    removed."""
    monkeypatch.setattr(plant_module, "MAX_FMU_BYTES", 4 << 20)
    fmu = _rewrite(swap("nominal"), tmp_path / "liar.fmu",
                   add=[("resources/zeros.bin", bytes(8 << 20))])
    real = zipfile.ZipFile.infolist

    def lying(self):
        infos = real(self)
        for i in infos:
            if i.filename == "resources/zeros.bin":
                i.file_size = 0
        return infos
    monkeypatch.setattr(zipfile.ZipFile, "infolist", lying)
    with pytest.raises(PlantFileError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("liar.fmu: ") and "resources/zeros.bin" in text, text
    assert _leftovers(private_tmp) == []


def test_too_many_entries_refused(swap, tmp_path, private_tmp, monkeypatch):
    monkeypatch.setattr(plant_module, "MAX_FMU_ENTRIES", 5)
    fmu = _rewrite(swap("nominal"), tmp_path / "many.fmu",
                   add=[(f"resources/f{i}", b"") for i in range(6)])
    with pytest.raises(PlantFileError, match=r"^many\.fmu: the FMU archive has 9 entries, more "
                                             r"than the 5"):
        Plant(fmu)


@pytest.mark.parametrize("identifier", ["../SwapPlant", "sub/SwapPlant", "..\\\\SwapPlant"])
def test_model_identifier_with_a_path_is_refused(swap, tmp_path, private_tmp, identifier):
    """A modelIdentifier with ../ made the master load a library outside the archive."""
    def edit(name, data):
        if name != "modelDescription.xml":
            return data
        return data.replace(b'modelIdentifier="SwapPlant"',
                            f'modelIdentifier="{identifier}"'.encode())
    fmu = _rewrite(swap("nominal"), tmp_path / "ident.fmu", edit=edit)
    with pytest.raises(ContractError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("ident.fmu breaks the plant contract") and "modelIdentifier" in text
    assert "not a plain name" in text, text
    assert _leftovers(private_tmp) == []


def test_garbage_binary_refused_in_one_line(swap, tmp_path, private_tmp):
    cwd = os.getcwd()
    fmu = _rewrite(swap("nominal"), tmp_path / "garbage.fmu",
                   drop=("binaries/linux64/SwapPlant.so",),
                   add=[("binaries/linux64/SwapPlant.so", b"\x7fELF this is not a library")])
    with pytest.raises(PlantFileError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("garbage.fmu: its binary for this platform cannot be used: ")
    assert "\n" not in text and "armimp-fmu" not in text, text
    assert os.getcwd() == cwd  # fmpy changed into the binary's folder
    assert _leftovers(private_tmp) == []


def test_binary_without_fmi_functions_refused_in_one_line(swap, tmp_path, private_tmp):
    import subprocess

    src = tmp_path / "empty.c"
    src.write_text("int not_an_fmu(void) { return 0; }\n")
    lib = tmp_path / "empty.so"
    subprocess.run([os.environ.get("CC", "cc"), "-shared", "-fPIC", "-o", str(lib), str(src)],
                   check=True)
    fmu = _rewrite(swap("nominal"), tmp_path / "nofuncs.fmu",
                   drop=("binaries/linux64/SwapPlant.so",),
                   add=[("binaries/linux64/SwapPlant.so", lib.read_bytes())])
    with pytest.raises(PlantFileError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("nofuncs.fmu: its binary for this platform cannot be used: ")
    assert "fmi2" in text and "\n" not in text, text
    assert _leftovers(private_tmp) == []


def test_missing_binary_and_damaged_archive_refused_naming_the_fmu(swap, tmp_path, private_tmp):
    fmu = _rewrite(swap("nominal"), tmp_path / "nobin.fmu", drop=("binaries/linux64/SwapPlant.so",))
    with pytest.raises(PlantFileError, match=r"^nobin\.fmu has no binary for this platform"):
        Plant(fmu)
    data = swap("nominal").read_bytes()
    damaged = tmp_path / "damaged.fmu"
    # the binary's compressed bytes overwritten: the directory still reads, the data not
    with zipfile.ZipFile(swap("nominal")) as z:
        info = z.getinfo("binaries/linux64/SwapPlant.so")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 50
    damaged.write_bytes(data[:start] + bytes(200) + data[start + 200:])
    with pytest.raises(PlantFileError, match=r"^damaged\.fmu: cannot extract the FMU archive"):
        Plant(damaged)
    assert _leftovers(private_tmp) == []


def test_extracted_folder_removed_on_close_and_stale_ones_at_the_next_run(swap, private_tmp):
    stale = private_tmp / f"armimp-fmu-{_dead_pid()}-abc123"
    (stale / "binaries").mkdir(parents=True)
    alive = private_tmp / f"armimp-fmu-{os.getppid()}-keep"  # a living process's: kept
    alive.mkdir()
    with Plant(swap("nominal")) as plant:
        mine = [n for n in _leftovers(private_tmp) if n.startswith(f"armimp-fmu-{os.getpid()}-")]
        assert len(mine) == 1 and os.path.isdir(plant._unzip_dir)
        assert not stale.exists() and alive.exists()
    assert _leftovers(private_tmp) == [alive.name]


def _dead_pid():
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# ------------------------------------------------------------------------ contract edges
def test_input_outside_the_contract_is_listed_by_info_and_can_be_set(swap, capsys):
    """motor_enable (start 0, as Simulink exports carry): listed with its start value; set
    to 1 the trial equals the nominal plant's bit for bit; left at 0 it is warned about."""
    assert cli_main(["info", str(swap("motor_enable"))]) == 0
    out = capsys.readouterr().out
    assert "1 input(s) outside the contract: motor_enable (start 0.0)" in out, out
    assert "  motor_enable = 0.0" in out
    setup = Setup.reference(0, 0)
    with Plant(swap("nominal")) as plant:
        nominal = simulate_trial(setup, perturbed_dof=1, duration_s=0.5, plant=plant, seed=4)
    with Plant(swap("motor_enable")) as plant:
        assert plant.describe()["inputs_outside_contract"] == {"motor_enable": 0.0}
        enabled = simulate_trial(setup, perturbed_dof=1, duration_s=0.5, plant=plant, seed=4,
                                 parameters={"motor_enable": 1.0})
        with pytest.warns(PlantWarning, match=r"motor_enable\.fmu: input\(s\) outside the "
                                              r"contract held at their start values: "
                                              r"motor_enable = 0\.0"):
            try:
                simulate_trial(setup, perturbed_dof=1, duration_s=0.5, plant=plant, seed=4)
            except DivergenceError as exc:  # the motor off: the error names the input too
                assert "held at their start values (motor_enable = 0.0): if one disables" \
                    in str(exc) and "--plant-parameter NAME=VALUE" in str(exc), str(exc)
    for sig in ("theta", "tau_h", "tau_m"):
        np.testing.assert_array_equal(enabled.signal(sig), nominal.signal(sig), err_msg=sig)
    assert enabled.meta["simulation"]["parameters"] == {"motor_enable": 1.0}


def test_plant_parameter_option_sets_an_input_on_the_command_line(swap, tmp_path, capsys):
    out = tmp_path / "enabled"
    rc = cli_main(["simulate", "--out", str(out), "--duration", "0.3", "--fmu",
                   str(swap("motor_enable")), "--plant-parameter", "motor_enable=1"])
    assert rc == 0
    import json
    meta = json.loads((tmp_path / "enabled.json").read_text())
    assert meta["simulation"]["parameters"]["motor_enable"] == 1.0
    with pytest.raises(SystemExit):
        cli_main(["simulate", "--out", str(out), "--plant-parameter", "motor_enable"])
    assert "expected NAME=VALUE with a finite number, got 'motor_enable'" in capsys.readouterr().err


def test_friction_the_plant_lacks_is_refused_by_name(swap):
    """--friction 3 on a plant without friction parameters was ignored silently (F3 = F0)."""
    with Plant(swap("nominal")) as plant:
        with pytest.raises(ParameterError) as err:
            simulate_trial(Setup.reference(3, 0), perturbed_dof=1, duration_s=0.2, plant=plant)
        simulate_trial(Setup.reference(0, 0), perturbed_dof=1, duration_s=0.2, plant=plant)
    text = str(err.value)
    assert text.startswith("nominal.fmu has no parameter friction.Fc[1], friction.Fc[2]"), text
    assert "ignored silently" in text


@pytest.mark.filterwarnings("ignore::orchestrator.errors.PlantWarning")
def test_fmi3_clocked_outputs_refused_up_front(tmp_path):
    """A clock and an output it clocks: refused naming both (was "contract: OK", then a
    divergence at t = 0.179 s)."""
    fmus = pytest.importorskip("fmus")
    src = fmus.build_fmu(tmp_path / "fmi3", fmi_version=3)

    def edit(name, data):
        if name != "modelDescription.xml":
            return data
        text = data.decode()
        text = text.replace('<Float64 name="tau_h[1]"', '<Float64 clocks="999" name="tau_h[1]"', 1)
        text = text.replace("</ModelVariables>",
                            '<Clock name="tick" valueReference="999" causality="input" '
                            'variability="discrete" intervalVariability="constant" '
                            'intervalDecimal="0.01"/></ModelVariables>', 1)
        return text.encode()
    fmu = _rewrite(src, tmp_path / "clocked.fmu", edit=edit)
    assert b'clocks="999"' in zipfile.ZipFile(fmu).read("modelDescription.xml")
    with pytest.raises(ContractError) as err:
        Plant(fmu)
    text = str(err.value)
    assert text.startswith("clocked.fmu breaks the plant contract"), text
    assert "clock(s) tick" in text and "clocked variable(s) tau_h[1]" in text, text


def test_once_per_process_plant_with_failing_reset_runs_every_trial(swap):
    """One instance at a time and a failing reset: the old instance is freed before the new
    one is made (was: 1 done, 3 failed)."""
    setup = Setup.reference(0, 0)
    with Plant(swap("once_reset_fails")) as plant:
        assert plant.describe()["once_per_process"] is True
        with pytest.warns(PlantWarning, match="fmi2Reset"):
            trials = [simulate_trial(setup, perturbed_dof=k, duration_s=0.3, plant=plant, seed=1)
                      for k in (1, 2, 1)]
        assert plant.reinstantiated >= 1
    np.testing.assert_array_equal(trials[0].signal("theta"), trials[2].signal("theta"))


def test_plant_instantiable_once_ever_gets_a_fresh_worker_per_grid_trial(swap, tmp_path):
    """A plant that refuses a second instance in a process even after the first is freed:
    in one process the second trial fails naming the FMU and the plant's own log line; a
    grid runs each trial in a fresh worker and gets them all."""
    fmu = swap("once_ever_reset_fails")
    setup = Setup.reference(0, 0)
    with Plant(fmu) as plant:
        simulate_trial(setup, perturbed_dof=1, duration_s=0.2, plant=plant)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PlantWarning)
            with pytest.raises(FMUCallError) as err:
                simulate_trial(setup, perturbed_dof=2, duration_s=0.2, plant=plant)
    text = str(err.value)
    assert "once_ever_reset_fails.fmu: fmi2Instantiate returned NULL" in text, text
    assert "this plant was instantiated in this process before" in text
    m = run_grid(tmp_path / "grid", workers=1, progress=False, friction_levels=(0,),
                 resolution_levels=(0, 1), perturbation_levels=(3,), dofs=(1, 2),
                 duration_s=0.2, fmu_path=fmu)
    assert m["n_done"] == 4 and m["n_failed"] == 0, m["trials"]


def test_instantiate_returning_null_names_the_fmu_and_its_log_line(swap, private_tmp):
    with pytest.raises(FMUCallError) as err:
        Plant(swap("no_licence"))
    text = str(err.value)
    assert text.startswith("no_licence.fmu: fmi2Instantiate returned NULL"), text
    assert "licence server 27000@licence.example unreachable: no licence for SwapPlant" in text
    assert _leftovers(private_tmp) == []
    assert re.search(r"\[ERROR\]", text)


def test_contract_plant_lists_no_extra_inputs(swap, capsys):
    assert cli_main(["info", str(swap("nominal"))]) == 0
    out = capsys.readouterr().out
    assert "outside the contract" not in out


def test_plant_parameters_from_the_environment_reach_every_trial(swap, monkeypatch):
    """armimp diagnose --plant-parameter sets ARMEXO_PLANT_PARAMETERS (its workers inherit
    it): the motor enabled, the trial is the nominal plant's."""
    from orchestrator.errors import SetupError
    from orchestrator.trial import env_plant_parameters
    setup = Setup.reference(0, 0)
    with Plant(swap("nominal")) as plant:
        nominal = simulate_trial(setup, perturbed_dof=1, duration_s=0.3, plant=plant, seed=4)
    monkeypatch.setenv("ARMEXO_PLANT_PARAMETERS", '{"motor_enable": 1}')
    with Plant(swap("motor_enable")) as plant:
        enabled = simulate_trial(setup, perturbed_dof=1, duration_s=0.3, plant=plant, seed=4)
    np.testing.assert_array_equal(enabled.signal("tau_h"), nominal.signal("tau_h"))
    monkeypatch.setenv("ARMEXO_PLANT_PARAMETERS", '{"motor_enable": "on"}')
    with pytest.raises(SetupError, match=r"ARMEXO_PLANT_PARAMETERS = .*expected a JSON "
                       r"object of finite numbers"):
        env_plant_parameters()


def test_diagnose_takes_plant_parameter(monkeypatch):
    from orchestrator.cli import build_parser
    args = build_parser().parse_args(["diagnose", "trials", "--out", "r",
                                      "--plant-parameter", "motor_enable=1"])
    assert args.plant_parameter == [("motor_enable", 1.0)]
