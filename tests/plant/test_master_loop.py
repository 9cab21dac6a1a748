"""fmpy.simulate_fmu and a plain stepping loop agree under the same piecewise-constant input."""
from __future__ import annotations

import numpy as np

from fmus import reference_result as ref

from .helpers import run_plain


def test_simulate_fmu_equals_plain_loop(fmu_path, slave):
    sim = ref.simulate(fmu_path)
    n = int(round(ref.STOP_TIME / ref.STEP))
    tk = np.arange(n + 1) * ref.STEP
    run = run_plain(slave, {}, ref.reference_input(tk)[:-1], Ts=ref.STEP, outputs=ref.OUTPUTS)
    np.testing.assert_allclose(sim[:, 0], run.t, rtol=0, atol=1e-12)
    for i, name in enumerate(ref.OUTPUTS):
        # the same FMI calls in the same order: identical to rounding
        np.testing.assert_allclose(sim[:, 3 + i], run.y[name], rtol=1e-12, atol=1e-15, err_msg=name)


def test_reference_result_csv_is_reproduced(fmu_path):
    """The committed reference result of the default experiment is what the FMU computes."""
    data = np.loadtxt(ref.Path(ref.__file__).parent / "ArmExoPlant" / "reference_result.csv",
                      delimiter=",", skiprows=1)
    sim = ref.simulate(fmu_path)
    np.testing.assert_allclose(sim, data, rtol=1e-9, atol=1e-12)


def test_reading_outputs_does_not_change_the_trajectory(make_slave):
    """Outputs are computed on demand; whether and how often they are read changes nothing."""
    from fmus.variables import VR

    results = []
    for read_every_step in (True, False):
        slave, _ = make_slave()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(300):
            slave.setReal([VR["tau_m[1]"], VR["tau_m[2]"]], [np.sin(0.05 * k), 0.5 * np.cos(0.03 * k)])
            slave.doStep(k * 1e-3, 1e-3)
            if read_every_step:
                slave.getReal([VR["tau_h[1]"], VR["theta[2]"]])
        results.append(slave.getReal([VR[n] for n in ("theta[1]", "theta[2]", "omega[1]", "tau_h[2]")]))
    assert results[0] == results[1]
