"""What a lab publishes: values rounded to their intervals, K, B, I in that order, I for one
joint and M for n, a delay at its search bound without an interval, the Bode plot's
frequency axis and low-coherence marks, and the paper's Figs. 2-3 (small multiples, markers
without lines, the VAF target on the axis)."""

from types import SimpleNamespace

import numpy as np
import pytest

from estimation import lab
from estimation.conditions import Condition
from estimation.labreport import (PLOT_BEYOND_BAND, bode, kbi_columns, low_coherence_spans,
                                  parameters_markdown, plot_top_hz, write_parameters)
from estimation.numbers import decimals_of, plus_minus, round_pair
from estimation.reflex import delay_text
from estimation.report import VAF_TARGET, fig2, fig3, marker_indices
from estimation.synthetic import position_trial


@pytest.mark.parametrize("value, ci, text", [
    (79.467, 1.599, "79.5 ± 1.6"),          # the old caption's 79.47 +- 1.599
    (0.0153, 0.001706, "0.0153 ± 0.0017"),  # 0.001706: 2 significant digits
    (25.02, 0.996, "25.0 ± 1.0"),           # 0.996 rounds up into a new digit
    (0.01197, 9.223e-05, "0.011970 ± 0.000092"),
    (102.63, 11.09, "103 ± 11"),
    (1234.5, 123.4, "1230 ± 120"),          # interval in the tens
    (-0.001, 0.3, "0.00 ± 0.30"),           # no "-0.00"
    (6.198, 12.92, "6 ± 13"),
])
def test_plus_minus_rounds_the_interval_to_two_digits_and_the_value_alike(value, ci, text):
    assert plus_minus(value, ci) == text


def test_no_interval_gives_the_value_alone_and_bad_widths_are_refused():
    assert round_pair(10.0, 0.0) == ("10", "")
    assert plus_minus(10.0, float("nan"), "ms") == "10 ms"
    assert decimals_of(0.0996) == 2 and decimals_of(0.0994) == 3
    with pytest.raises(ValueError, match="positive and finite"):
        decimals_of(0.0)


def test_parameter_columns_in_k_b_i_order():
    cols = ["label", "element", "M [kg m^2]", "M_ci [kg m^2]", "B [N m s/rad]",
            "B_ci [N m s/rad]", "K [N m/rad]", "K_ci [N m/rad]", "M_range_min [kg m^2]",
            "K_range_min [N m/rad]", "R2", "err_M [%]", "err_K [%]", "G [N m s/rad]"]
    assert kbi_columns(cols) == [
        "label", "element", "K [N m/rad]", "K_ci [N m/rad]", "K_range_min [N m/rad]",
        "err_K [%]", "B [N m s/rad]", "B_ci [N m s/rad]", "M [kg m^2]", "M_ci [kg m^2]",
        "M_range_min [kg m^2]", "err_M [%]", "R2", "G [N m s/rad]"]


@pytest.fixture(scope="module")
def ankle():
    trial = position_trial(K=150.0, B=1.5, I=0.015, seed=3, duration_s=20.0)
    return lab.analyse(lab.Unit("ankle", [trial], "test"))


def test_parameters_files_order_k_b_i_and_round(ankle, tmp_path):
    write_parameters([ankle], tmp_path)
    header = (tmp_path / "parameters.csv").read_text().splitlines()[0].split(",")
    order = [header.index(c) for c in ("K [N m/rad]", "B [N m s/rad]", "M [kg m^2]")]
    assert order == sorted(order)
    md = parameters_markdown([ankle])
    assert "| element | K [N m/rad] | B [N m s/rad] | I [kg m^2] |" in md
    k, ci = ankle.fit.K[0, 0], ankle.fit.K_ci[0, 0]
    assert f"| Z | {plus_minus(k, ci)} |" in md and "+-" not in md.split("- warning")[0]


def _fake(n, M):
    fit = SimpleNamespace(M=np.array(M), B=np.eye(n), K=100 * np.eye(n),
                          M_ci=np.full((n, n), 1e-4), B_ci=np.full((n, n), 0.01),
                          K_ci=np.ones((n, n)), r2=np.ones((n, n)))
    return SimpleNamespace(fit=fit, n_dof=n, coherence_band=np.ones((n, n)), method="full")


def test_negative_inertia_is_I_for_one_joint_and_M_for_n():
    one = lab.fit_warnings(_fake(1, [[-0.0153]]), lab.AnalysisOptions())
    assert "non-physical fit: I = -0.0153 kg m^2 is negative (inertia)" in one
    assert not any(w.startswith("non-physical fit: M") for w in one)
    two = lab.fit_warnings(_fake(2, [[-0.1, 0.0], [0.0, 0.2]]), lab.AnalysisOptions())
    assert any(w.startswith("non-physical fit: M_11 = -0.1 kg m^2") for w in two)


def test_delay_at_its_search_bound_has_no_interval():
    def fit(d, ci):
        return SimpleNamespace(values={"delay_ms": d}, ci={"delay_ms": ci},
                               options={"delay_ms": (10.0, 120.0)})
    assert delay_text(fit(10.0, 0.0)) == "10.0 ms (at the search bound)"
    assert delay_text(fit(120.0, 0.0), compact=True) == "120.0 ms (at the search bound)"
    assert delay_text(fit(52.83, 2.71)) == "52.8 ± 2.7 ms"
    assert delay_text(fit(52.83, 2.71), compact=True) == "52.8±2.7 ms"


def test_low_coherence_spans_and_plot_top():
    f = np.arange(0.0, 10.0, 0.5)
    c = np.ones(f.size)
    c[[4, 5, 6, 12]] = 0.2                     # 2.0-3.0 Hz and 6.0 Hz
    assert low_coherence_spans(f, c) == [(1.75, 3.25), (5.75, 6.25)]
    r = SimpleNamespace(f_max=300.0, band_hz=(0.0, 40.0))
    assert plot_top_hz(r) == PLOT_BEYOND_BAND * 40.0
    assert plot_top_hz(SimpleNamespace(f_max=50.0, band_hz=(0.0, 40.0))) == 50.0


def test_bode_axis_flags_and_notch(ankle):
    import matplotlib.pyplot as plt
    res = lab.LabResult(**{**ankle.__dict__, "flags": ["poor fit"]})
    res.coherence = ankle.coherence.copy()
    notch = (res.f > 4.0) & (res.f < 4.5)
    res.coherence[notch] = 0.1
    fig = bode(res)
    ax_m, ax_p, ax_c = fig.axes[:3]
    assert ax_m.get_xlim()[1] == pytest.approx(res.f[res.f <= plot_top_hz(res)][-1])
    flag = [t for t in ax_m.texts if t.get_text().startswith("FLAGGED")]
    assert flag and flag[0].get_position()[1] > 1.0   # above the axes, not on the data
    hatched = [p for p in ax_c.patches if p.get_hatch()]
    lo, hi = res.f[notch][0], res.f[notch][-1]
    assert any(p.get_x() <= lo and p.get_x() + p.get_width() >= hi for p in hatched)
    marked = ax_c.lines[1].get_ydata()               # the low-coherence bins, marked
    assert np.all(np.isfinite(marked[notch[(res.f > 0) & (res.f <= plot_top_hz(res))]]))
    plt.close(fig)


def test_fig2_small_multiples_one_error_row_per_condition():
    import trialformat as tf
    from estimation.accuracy import true_impedance
    f = np.linspace(0.1, 15.0, 60)
    arm = tf.reference.arm_matrices()
    Z = true_impedance(f, *arm)
    corners = [(0, 0), (0, 3), (3, 0), (3, 3)]
    curves = {Condition(fr, re, 3, "reference"): {"full_corrected": (f, (1 + 0.01 * j) * Z)}
              for j, (fr, re) in enumerate(corners)}
    fig = fig2(curves, arm, ["full_corrected"], "Table I")
    err = [ax for ax in fig.axes if ax.get_ylabel().startswith("error [%]")]
    assert len(err) == 4 * 4                          # 4 elements x 4 conditions
    assert {ax.get_ylabel().split("\n")[1] for ax in err} == {"F0R0", "F0R3", "F3R0", "F3R3"}
    one = [ax for ax in err if ax.get_ylabel().endswith("F3R3")][0]
    np.testing.assert_allclose(one.lines[0].get_ydata(), 3.0)   # 1.03 Z: 3 % everywhere
    assert all(ax.get_shared_y_axes().joined(err[0], ax) for ax in err)
    idx = [set(marker_indices(f, s, 4)) for s in range(4)]
    assert all(not (idx[a] & idx[b]) for a in range(4) for b in range(a + 1, 4))


def test_fig3_markers_without_lines_and_the_target_on_the_axis():
    rows = [{"variant": "v", "friction": fr, "resolution": 0, "perturbation": 3,
             **{f"{k}_{e}": (99.998 if k == "vaf" else 0.99998)
                for k in ("vaf", "r2") for e in ("11", "12", "21", "22")}}
            for fr in (0, 3)]
    fig = fig3(rows, "v")
    vaf_ax, r2_ax = fig.axes[:2]
    data = [ln for ln in vaf_ax.lines if ln.get_label().startswith("Z")]
    assert len(data) == 4 and all(ln.get_linestyle() == "None" for ln in data)
    lo, hi = vaf_ax.get_ylim()
    assert lo < VAF_TARGET < 100.0 <= hi
    assert any(np.allclose(ln.get_ydata(), VAF_TARGET) for ln in vaf_ax.lines)


def test_vaf_target_is_the_studys():
    from orchestrator.paper import TARGETS
    assert VAF_TARGET == TARGETS["vaf_min"]
