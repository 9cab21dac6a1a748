"""``simulate --rk4-step``: a nonsensical solver step is refused up front, naming the
option, the value and the accepted range (from the communication step and the plant's
declared limits), before any plant is loaded; a step in range still runs."""

import time

import pytest

from orchestrator.errors import RateError
from orchestrator.trial import MAX_RK4_STEPS_PER_COMM_STEP, check_rk4_step


@pytest.mark.parametrize("value", ["1e-20", "2e-3", "1e-10"])
def test_cli_refuses_out_of_range_rk4_step_up_front(value, tmp_path, capsys, monkeypatch):
    from orchestrator import cli
    import orchestrator.trial as trial_mod

    def no_plant(*a, **k):  # the refusal comes before any simulation
        raise AssertionError("simulate_trial called")
    monkeypatch.setattr(trial_mod, "simulate_trial", no_plant)
    t0 = time.perf_counter()
    assert cli.main(["simulate", "--rk4-step", value, "--duration", "0.5", "--out",
                     str(tmp_path / "a")]) == 1
    assert time.perf_counter() - t0 < 5
    err = capsys.readouterr().err
    assert f"--rk4-step {float(value)!r} s: outside the accepted range 1e-09 ... 0.001 s" \
        in err and "communication step 0.001 s" in err and "e.g. --rk4-step 1e-05 s" in err
    assert "set-up" not in err and "fmi2DoStep" not in err
    assert not (tmp_path / "a.csv").exists()


def test_range_follows_the_communication_step_and_the_plants_declared_limits():
    step = 1.0 / 1024
    check_rk4_step(step / MAX_RK4_STEPS_PER_COMM_STEP, step)  # the lower end is accepted
    with pytest.raises(RateError, match=r"--rk4-step 5e-10 s: outside the accepted range 9\.7656[23]e-10 \.\.\. "):
        check_rk4_step(5e-10, step, option="--rk4-step")
    with pytest.raises(RateError, match=r"rk4_step 1e-05 s: outside the accepted range "
                                        r"2e-05 \.\.\. 0\.0001 s .*P\.fmu declares rk4_step "
                                        r"min 2e-05 s, max 0\.0001 s"):
        check_rk4_step(1e-5, 1e-3, where="P.fmu", declared=(2e-5, 1e-4))
    with pytest.raises(RateError, match="does not divide"):
        check_rk4_step(3e-5, 1e-3, option="--rk4-step")
    check_rk4_step(1e-5, 1e-3, where="P.fmu", declared=(0.0, None))


def test_plant_parameter_rk4_step_refused_naming_the_plant(tmp_path):
    from orchestrator import Setup, simulate_trial
    with pytest.raises(RateError, match=r"rk4_step 1e-20 s: outside .*declares rk4_step min 0 s"):
        simulate_trial(Setup.reference(), perturbed_dof=1, duration_s=0.1,
                       parameters={"rk4_step": 1e-20})


def test_cli_refuses_rk4_step_given_twice_with_other_values(tmp_path, capsys, monkeypatch):
    from orchestrator import cli
    import orchestrator.trial as trial_mod

    seen = {}

    def fake(*a, parameters=None, **k):  # records what would be simulated
        seen["parameters"] = parameters
        raise AssertionError("simulate_trial called")
    monkeypatch.setattr(trial_mod, "simulate_trial", fake)
    assert cli.main(["simulate", "--rk4-step", "1e-5", "--plant-parameter", "rk4_step=5e-5",
                     "--duration", "0.5", "--out", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err
    assert "--rk4-step 1e-05 and --plant-parameter rk4_step=5e-05 disagree" in err
    assert not seen  # refused before any plant
    # the same value twice is no conflict
    with pytest.raises(AssertionError, match="simulate_trial called"):
        cli.main(["simulate", "--rk4-step", "1e-5", "--plant-parameter", "rk4_step=1e-5",
                  "--duration", "0.5", "--out", str(tmp_path / "b")])
    assert seen["parameters"] == {"rk4_step": 1e-5}


def test_cli_says_which_plant_runs_when_plant_and_fmu_are_both_given(reference_fmu,
                                                                     tmp_path, capsys,
                                                                     monkeypatch):
    from orchestrator import cli

    monkeypatch.delenv("ARMEXO_PLANT", raising=False)  # restored after main sets it

    assert cli.main(["--plant", "modelica", "simulate", "--fmu", str(reference_fmu),
                     "--duration", "0.3", "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert err.count("note:") == 1
    assert f"the plant is {reference_fmu} (--fmu); --plant modelica chooses" in err
