"""The torque perturbation of reference.md section 6 (paper, Table III)."""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfilt

from trialformat import reference as ref

from .errors import SetupError


def make_perturbation(level: int, seed: int, n_samples: int, n_dof: int = 2,
                      fs: float = 1000.0, perturbed_dof: int | None = None, *,
                      peak=None) -> np.ndarray:
    """Filtered uniform noise, scaled to the level's peak per joint.

    Uniform white noise on [-1, 1] at ``fs``, an 8th-order Butterworth low-pass at 15 Hz
    applied causally as second-order sections (``scipy.signal.sosfilt``), the first 2 s of
    filter transient discarded, each joint's column scaled so that ``max |tau_delta_j|``
    equals the level's peak.

    All ``n_dof`` columns are always drawn from one generator seeded with ``seed``, so
    column k is the same whether joint k is perturbed alone or with the others.

    Parameters
    ----------
    level : int
        Perturbation level 1-3 (peaks [3, 1.8], [6, 3.6], [9, 5.4] N m; three joints
        (reference-3dof.md): [3, 1.8, 0.6], [6, 3.6, 1.2], [9, 5.4, 1.8] N m).
    seed : int
        Seed of ``numpy.random.default_rng``.
    n_samples : int
        Number of samples N returned (after the discarded transient).
    n_dof : int
        Number of joints n.
    fs : float [Hz]
        Sampling rate.
    perturbed_dof : int or None
        1-based joint to perturb alone (other columns zero), or None for all joints.
    peak : sequence of float [N m], optional
        Peaks per joint overriding the level's (needed when n_dof is not 2 or 3).

    Returns
    -------
    ndarray [N m], shape (N, n_dof)
    """
    spec = ref.reference()["perturbation"]
    try:
        arm = {2: "2dof", 3: "3dof"}.get(n_dof, "2dof")  # the reference of n_dof joints
        peaks = np.asarray(ref.perturbation_peak(level, arm) if peak is None else peak,
                           dtype=float)
    except ValueError as exc:
        raise SetupError(str(exc)) from None
    if peaks.shape != (n_dof,):
        raise SetupError(f"perturbation peak has {peaks.size} values for n_dof={n_dof}; "
                         f"give peak= with one value per joint")
    if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise SetupError(f"n_samples must be a positive integer, got {n_samples!r}")
    if perturbed_dof is not None and not 1 <= perturbed_dof <= n_dof:
        raise SetupError(f"perturbed_dof must be None or in 1..{n_dof}, got {perturbed_dof!r}")
    n_discard = int(round(spec["discard_s"] * fs))
    rng = np.random.default_rng(seed)
    white = rng.uniform(-1.0, 1.0, size=(n_samples + n_discard, n_dof))
    sos = butter(spec["butterworth_order"], spec["cutoff_hz"], btype="low", fs=fs,
                 output="sos")
    filtered = sosfilt(sos, white, axis=0)[n_discard:]
    out = filtered * (peaks / np.max(np.abs(filtered), axis=0))
    if perturbed_dof is not None:
        keep = np.zeros(n_dof, dtype=bool)
        keep[perturbed_dof - 1] = True
        out[:, ~keep] = 0.0
    return out
