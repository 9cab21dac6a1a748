"""Analysis at the edges (issue 16): few Welch segments warned about, R^2 of every
element, a too-short all-joints trial refused per condition instead of aborting."""

from types import SimpleNamespace

import numpy as np
import pytest

import trialformat as tf
from estimation import EstimationError
from estimation.cli import main
from estimation.estimator import estimate_impedance
from estimation.lab import AnalysisOptions, Unit, analyse, fit_warnings
from estimation.synthetic import synthetic_trial


@pytest.fixture(scope="module")
def short_pair():
    return [synthetic_trial(perturbed_dof=k, duration_s=10.0, seed=k,
                            tau_noise_std_nm=0.05, name=f"j{k}") for k in (1, 2)]


def test_one_segment_warned_with_its_count_and_a_segment_that_works(short_pair):
    r = analyse(Unit("noisy", short_pair, "test"), AnalysisOptions(nperseg=8192))
    few = [w for w in r.warnings if w.startswith("few Welch averages")]
    assert len(few) == 1 and f"{r.n_segments} segment(s) of 8192" in few[0]
    assert r.n_segments < 8
    hint = int(few[0].split("--nperseg ")[1].split()[0])
    again = analyse(Unit("noisy", short_pair, "test"), AnalysisOptions(nperseg=hint))
    assert again.n_segments >= 8
    assert not [w for w in again.warnings if w.startswith("few Welch averages")]


def test_r2_warning_covers_off_diagonal_elements():
    n = 2
    fit = SimpleNamespace(M=np.eye(n), B=np.eye(n), K=np.eye(n), M_ci=np.zeros((n, n)),
                          B_ci=np.zeros((n, n)), K_ci=np.zeros((n, n)),
                          r2=np.array([[0.99, 0.40], [0.99, 0.99]]))
    result = SimpleNamespace(fit=fit, n_dof=n, coherence_band=np.ones((n, n)),
                             method="full", n_segments=20)
    warnings = fit_warnings(result, AnalysisOptions())
    assert [w for w in warnings if w.startswith("poor fit")] == [
        "poor fit: Z_12 R^2 = 0.400 (< 0.9); the second-order model may not describe the "
        "coupling of joints 1 and 2 in this band"]


def test_short_all_joints_trial_refused_clearly_not_singular_matrix():
    trial = synthetic_trial(perturbed_dof=None, duration_s=9.0, name="mimo9")
    with pytest.raises(EstimationError, match=r"1 Welch segment\(s\) of 8192 samples cannot "
                                              r"separate 2 joints.*use --nperseg 2048"):
        estimate_impedance([trial], method="closed_loop")
    estimate_impedance([trial], method="closed_loop", nperseg=2048, noverlap=1536,
                       nfft=2048)  # the suggested segment works


def test_lab_report_goes_on_past_a_failed_condition(tmp_path, capsys):
    for name, seconds in (("short", 9.0), ("long", 30.0)):
        tf.write_trial(tmp_path / "in" / name,
                       synthetic_trial(perturbed_dof=None, duration_s=seconds, name=name))
    rc = main(["figures", str(tmp_path / "in"), "--out", str(tmp_path / "out"), "--kind",
               "lab"])
    captured = capsys.readouterr()
    assert rc == 1  # one condition failed, said per condition
    assert "error: short: " in captured.err and "cannot separate 2 joints" in captured.err
    assert "Singular matrix" not in captured.err
    assert (tmp_path / "out" / "frf_long.csv").is_file()
    assert not (tmp_path / "out" / "frf_short.csv").exists()


def test_paper_report_skips_the_short_all_joints_trial_per_condition(tmp_path, capsys):
    for k in (1, 2):
        tf.write_trial(tmp_path / f"dof{k}", synthetic_trial(perturbed_dof=k, duration_s=12.0,
                                                             seed=k, name=f"dof{k}"))
    tf.write_trial(tmp_path / "dofall", synthetic_trial(perturbed_dof=None, duration_s=9.0,
                                                        name="dofall"))
    rc = main(["figures", str(tmp_path), "--out", str(tmp_path / "report"), "--kind", "paper"])
    err = capsys.readouterr().err
    assert rc == 0 and (tmp_path / "report" / "table_conditions.csv").is_file()
    assert "skipped:" in err and "cannot separate 2 joints" in err
