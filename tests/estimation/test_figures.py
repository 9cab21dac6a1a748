"""What the figures show and what ``figures`` accepts: phase unwrapping and masking, the
n x n layout for three joints, titles naming the truth and the conditions drawn, stems."""

import numpy as np
import pytest

import trialformat as tf
from estimation import EstimationError
from estimation.cli import main
from estimation.conditions import Condition
from estimation.labreport import bode, parameters_markdown
from estimation.lab import Unit, analyse
from estimation.report import fig2, fig3, trial_paths, unwrapped_phase_deg
from estimation.synthetic import (ARM_3DOF, CONTROLLER_3DOF, PEAK_3DOF, position_trial,
                                  synthetic_trial)


def test_phase_unwrapped_through_180_deg():
    # A second-order impedance K - I w^2 + j B w crosses 180 deg only through noise; build
    # a phase that runs 0 -> 200 deg, whose wrapped angle jumps to -160 deg.
    theta = np.radians(np.linspace(0.0, 200.0, 400))
    z = 3.0 * np.exp(1j * theta)
    assert np.abs(np.diff(np.degrees(np.angle(z)))).max() > 300  # the bars of before
    np.testing.assert_allclose(unwrapped_phase_deg(z), np.degrees(theta), atol=1e-9)


def test_phase_masked_where_meaningless_and_noise_adds_no_jump():
    rng = np.random.default_rng(1)
    theta = np.radians(np.linspace(10.0, 170.0, 300))
    z = np.exp(1j * theta)
    z[100:150] = np.exp(1j * rng.uniform(-np.pi, np.pi, 50))  # incoherent stretch
    valid = np.ones(z.size, bool)
    valid[100:150] = False
    ph = unwrapped_phase_deg(z, valid)
    assert np.isnan(ph[100:150]).all()
    np.testing.assert_allclose(ph[valid], np.degrees(theta[valid]), atol=1e-9)


def _curves(n, corners):
    f = np.linspace(0.1, 15.0, 60)
    arm = ARM_3DOF if n == 3 else tf.reference.arm_matrices()
    from estimation.accuracy import true_impedance
    Z = true_impedance(f, *arm)
    return arm, {Condition(fr, re, 3, "reference"): {"full_corrected": (f, 1.01 * Z)}
                 for fr, re in corners}


def test_fig2_three_joints_is_a_grid_naming_its_truth():
    arm, curves = _curves(3, [(0, 0)])
    fig = fig2(curves, arm, ["full_corrected"], "the 3-joint reference (reference-3dof)")
    w, h = fig.get_size_inches()
    assert h > w  # an n x n grid of element blocks, not a strip of 9 columns
    title = fig._suptitle.get_text()
    assert "reference-3dof" in title and "Table I" not in title
    assert "one condition (friction 0, resolution 0)" in title and "four" not in title
    titled = sorted(ax.get_title() for ax in fig.axes if ax.get_title())
    assert titled == sorted(f"Z{i}{k}" for i in (1, 2, 3) for k in (1, 2, 3))
    # Column k holds Z_ik: each element block sits in the column of its k.
    cols = {ax.get_title(): round(ax.get_position().x0, 3) for ax in fig.axes
            if ax.get_title()}
    assert cols["Z13"] == cols["Z23"] == cols["Z33"] > cols["Z12"]


def test_fig2_two_joints_four_corners_and_fig3_title_counts():
    arm, curves = _curves(2, [(0, 0), (0, 3), (3, 0), (3, 3)])
    title = fig2(curves, arm, ["full_corrected"], "Table I")._suptitle.get_text()
    assert "vs Table I, the four corner conditions" in title
    rows = [{"variant": "v", "friction": 0, "resolution": 0, "perturbation": 3,
             **{f"{k}_{e}": 99.0 for k in ("vaf", "r2") for e in ("11", "12", "21", "22")}}]
    t3 = fig3(rows, "v")._suptitle.get_text()
    assert "VAF and R²" in t3 and "(1 condition)" in t3


@pytest.fixture(scope="module")
def one_condition(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stems")
    for k in (1, 2):
        tf.write_trial(folder / f"dof{k}", synthetic_trial(perturbed_dof=k, seed=k,
                                                           duration_s=12.0))
    return folder


def test_figures_accepts_stems_like_estimate(one_condition, tmp_path, capsys):
    stems = [str(one_condition / "dof1"), str(one_condition / "dof2")]
    assert trial_paths(stems) == [one_condition / "dof1.csv", one_condition / "dof2.csv"]
    assert main(["estimate", *stems]) == 0
    assert main(["figures", *stems, "--out", str(tmp_path / "paper")]) == 0
    assert (tmp_path / "paper" / "fig2_impedance.png").is_file()
    with pytest.raises(EstimationError, match="nope"):
        trial_paths([str(one_condition / "nope")])


def _ankle():
    return analyse(Unit("ankle", [position_trial(K=150.0, B=1.5, I=0.015, seed=1)], "test"))


def test_one_joint_inertia_is_I_in_table_and_bode():
    r = _ankle()
    md = parameters_markdown([r])
    assert "| I [kg m^2] |" in md and "| M [" not in md
    fig = bode(r)
    caption = "\n".join(t.get_text() for t in fig.texts)
    title = fig._suptitle.get_text()
    assert "M = " not in caption + title and " M " not in caption
    # the short title: the recording and K, B, I (in that order) with units and intervals
    assert title.startswith("ankle: K = ")
    assert title.index("K = ") < title.index("B = ") < title.index("I = ")
    assert "N m/rad" in title and "N m s/rad" in title and "kg m²" in title
    assert "+-" not in caption + title and "±" in title


def test_a_long_bode_title_fits_inside_the_figure():
    """A long label and many digits (co-contract: "K = 249.993 ... I = 0.01499999 ±
    0.0000008") were clipped on both sides: the title wraps to fit the figure."""
    r = _ankle()
    r.label = "subject 07, right ankle, condition co-contract, trials 1-6, session 2"
    fig = bode(r)
    renderer = fig.canvas.get_renderer()
    box, title = fig.bbox, fig._suptitle.get_window_extent(renderer)
    assert box.x0 <= title.x0 and title.x1 <= box.x1, (title, box)
    assert box.y0 <= title.y0 and title.y1 <= box.y1, (title, box)
    assert "K = " in fig._suptitle.get_text() and "I = " in fig._suptitle.get_text()
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_three_joint_bode_is_a_grid_with_phase_masked_out_of_band():
    trials = [synthetic_trial(perturbed_dof=k, arm=ARM_3DOF, controller=CONTROLLER_3DOF,
                              peak=PEAK_3DOF, seed=10 + k, duration_s=20.0,
                              theta_noise_std_rad=1e-5, tau_noise_std_nm=0.02)
              for k in (1, 2, 3)]
    r = analyse(Unit("arm3", trials, "test"))
    fig = bode(r)
    w, h = fig.get_size_inches()
    assert h > w
    phase_axes = [ax for ax in fig.axes if ax.get_ylabel() == "phase [deg]"]
    assert len(phase_axes) == 9
    for ax in phase_axes:
        y = ax.lines[0].get_ydata()  # the estimate
        finite = y[np.isfinite(y)]
        assert np.abs(np.diff(finite)).max() < 90  # no +-180 deg bars


def test_paper_kind_of_three_joints_compares_with_reference_3dof(tmp_path, capsys):
    for k in (1, 2, 3):
        tf.write_trial(tmp_path / "in" / f"arm3_dof{k}", synthetic_trial(
            perturbed_dof=k, arm=ARM_3DOF, controller=CONTROLLER_3DOF, peak=PEAK_3DOF,
            seed=20 + k, duration_s=12.0))
    assert main(["figures", str(tmp_path / "in"), "--kind", "paper", "--out",
                 str(tmp_path / "rep"), "--compare", "none"]) == 0
    legend = (tmp_path / "rep" / "table_summary.md").read_text()
    assert "against the 3-joint reference (reference-3dof)" in legend
    assert "Table I" not in legend
