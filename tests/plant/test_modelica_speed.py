"""The speed work on the exported plant changes no result (fmus/modelica_build.py).

The build compiles the generated rhs once per combination of the effect switches, with the
switches as constants and the RK4 loop over the states that combination can change; the
FMU falls back to a generic loop (the switches read from the parameters) otherwise.  Here
every combination's loop is compared, bit for bit, with the generic loop of the same
sources (compiled with ``-DMD_FORCE_GENERIC``), and the exp() cut of the Stribeck curve is
checked against the rounding it relies on.  Speed figures: bench/bench_modelica_export.py.
"""
from __future__ import annotations

import itertools
import math
import os
import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy import simulate_fmu

from fmus import modelica_build as mb
from fmus.build import CFLAGS
from fmus.variables import friction_parameters

#: parameters that switch each of mb.SWITCHES on (the values of the agreement tests)
SWITCH_ON = {
    "actuator_lag.on": {"actuator_lag.time_constant_s": 0.003},
    "transmission_compliance.on": {f"transmission_compliance.{p}[{j}]": v
                                   for p, v in (("k_t", 300.0), ("c_t", 0.5)) for j in (1, 2)},
    "interface_compliance.on": {f"interface_compliance.{p}[{j}]": v
                                for p, v in (("k_s", 400.0), ("c_s", 2.0)) for j in (1, 2)},
    "torque_sensor_lag.on": {"torque_sensor_lag.time_constant_s": 0.002},
    "robot.tilted": {"gravity.tilt_deg": 10.0},
}
OUTPUTS = [f"{s}[{j}]" for s in ("theta", "tau_h", "omega", "tau_act", "friction.tau_f", "friction.z",
                                 "theta_link", "arm.theta") for j in (1, 2)]
T_END, H = 0.3, 1e-3


@pytest.fixture(scope="module")
def exported():
    try:
        return mb.default_fmu_path(n=2)
    except mb.ExporterUnavailable as exc:
        pytest.skip(f"the Modelica plant cannot be exported here: {exc}")


@pytest.fixture(scope="module")
def generic(exported, tmp_path_factory):
    """A copy of the exported FMU whose binary is compiled from its own ``sources/`` with
    ``-DMD_FORCE_GENERIC``: the generic RK4 loop for every parameter set."""
    if not sys.platform.startswith("linux"):
        pytest.skip("rebuilds the linux64 binary")
    out = tmp_path_factory.mktemp("generic")
    tree = out / "tree"
    with zipfile.ZipFile(exported) as z:
        z.extractall(tree)
        names = z.namelist()
    ident = re.search(r'modelIdentifier="([^"]+)"', (tree / "modelDescription.xml").read_text()).group(1)
    lib = tree / "binaries" / "linux64" / f"{ident}.so"
    src = tree / "sources"
    cmd = [os.environ.get("CC", "cc"), *[f for f in CFLAGS if f != "-Wextra"], "-DMD_FORCE_GENERIC",
           "-I", str(src), "-o", str(lib), str(src / f"{ident}_all.c"), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    fmu = out / exported.name
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for name in names:
            if not name.endswith("/"):
                z.write(tree / name, name)
    return fmu


def _input():
    t = np.arange(int(round(T_END / H)) + 1) * H
    sig = np.zeros(len(t), dtype=[("time", float), ("tau_m[1]", float), ("tau_m[2]", float)])
    sig["time"] = t
    sig["tau_m[1]"] = 0.8 * np.sin(2 * np.pi * 1.3 * t) + 0.3 * np.sin(2 * np.pi * 6.0 * t)
    sig["tau_m[2]"] = 0.5 * np.sin(2 * np.pi * 2.1 * t) + 0.2 * np.sin(2 * np.pi * 9.0 * t)
    return sig


def _run(path, params):
    res = simulate_fmu(str(path), start_values=dict(params), input=_input(), output=OUTPUTS,
                       stop_time=T_END, step_size=H, output_interval=H, fmi_type="CoSimulation")
    return np.column_stack([res[x] for x in OUTPUTS])


def test_each_switch_combination_loop_equals_the_generic_loop_bit_for_bit(exported, generic):
    """32 combinations (with LuGre friction level 2, so that z moves): the specialised loop
    (switches constant, only the states they leave changing) gives the generic loop's
    trajectory exactly; the generic loop is what the agreement tests' structure computes."""
    combos = list(itertools.product((0, 1), repeat=len(mb.SWITCHES)))
    assert len(combos) == 32
    differing = []
    for bits in combos:
        params = dict(friction_parameters(2))
        for name, on in zip(mb.SWITCHES, bits):
            if on:
                params.update(SWITCH_ON[name])
        a, b = _run(exported, params), _run(generic, params)
        assert np.max(np.abs(a[:, :2])) > 1e-4  # the plant moves
        if not np.array_equal(a, b):
            differing.append((bits, float(np.max(np.abs(a - b)))))
    assert not differing, differing


def test_generated_code_has_one_loop_per_switch_combination(exported):
    c = mb.generated_c(mb.export(2))
    assert len(re.findall(r"^static int md_rk4_v\d+\(Snapshot", c, re.M)) == 32
    # the rigid one (every switch off) integrates theta_link, w_link and z only
    rigid = c[c.index("static int md_rk4_v0("):c.index("static int md_rk4_v1(")]
    states = [s["name"] for s in mb.export(2)["states"]]
    updated = sorted({states[int(k)] for k in re.findall(r"xt\[(\d+)\] = x\[\d+\] \+ h2", rigid)})
    assert updated == sorted(["friction.z[1]", "friction.z[2]", "theta_link[1]", "theta_link[2]",
                              "w_link[1]", "w_link[2]"])


@pytest.mark.parametrize("n", [2, 3])
def test_stribeck_exp_is_cut_for_every_joint(n):
    """The rewrite A + (B) * exp(E) -> md_add_exp(...) finds the Stribeck curve of each joint
    (if the exporter's text changes, this fails instead of the speed silently going)."""
    try:
        e = mb.export(n)
    except mb.ExporterUnavailable as exc:
        pytest.skip(str(exc))
    c = mb.generated_c(e)
    rhs = c[c.index("void md_rhs_sw("):]
    rhs = rhs[:rhs.index("\n}\n")]
    for j in range(1, n + 1):
        assert (f"md_add_exp(friction_Fc_{j}_, (friction_Fs_{j}_ - friction_Fc_{j}_), "
                f"-pow(friction_w_{j}_ / friction_ws, 2.0), p[NP + NU + ") in rhs
    assert "exp(" not in rhs.replace("md_add_exp(", "")


def _cut(a, b):
    """md_exp_cut of the generated C (the test below checks that it is written so)."""
    return math.log(a / abs(b)) - 56.0 * 0.6931471805599453 if a > 0 and b != 0 else -math.inf


@pytest.mark.parametrize("a, b", [(0.4, 0.2), (0.2, 0.1), (1.0, 3.0), (0.25, 1e-3), (5e-3, 2.0),
                                  (0.4, -0.1), (2.0 ** -3, 2.0 ** -3)])
def test_below_the_cut_the_sum_is_a_exactly(a, b):
    """Below the cut, a + b exp(e) == a in double precision (so skipping exp() changes no
    bit); 5 log 2 above it the sum differs from a (the cut is not vacuous)."""
    cut = _cut(a, b)
    for e in np.linspace(cut - 3.0, cut, 20001)[:-1]:
        assert a + b * math.exp(e) == a, e
    assert a + b * math.exp(cut + 5 * math.log(2.0)) != a


def test_no_cut_without_a_positive_a():
    assert "? log(a / fabs(b)) - 56.0 * 0.6931471805599453 : -INFINITY" in mb._ADD_EXP  # = _cut
    assert _cut(0.0, 0.2) == -math.inf and _cut(-0.1, 0.2) == -math.inf and _cut(0.4, 0.0) == -math.inf
