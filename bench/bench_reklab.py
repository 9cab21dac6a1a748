"""The lab estimator on the five measured ankle recordings, next to an independent estimate.

Reads ``../shared/data/reklab-ankle/experimental_data.mat`` (NLID ``nldat`` objects, read
with mat-io; GPL data: read in place, never copied; the script says so and stops when it
is absent). Each recording becomes a 1-joint position-perturbation trial in memory (angle
``pos1`` [rad], torque ``tq1`` [N m] with its sign reversed, as the data's README states:
declared ``sensors.torque_sign = -1``; 1 kHz), estimated by ``estimation.lab.analyse`` with
default options (direct method: no reference recorded; band from the data), twice
(the numbers must be identical), and once more through a CSV written and read back by
trialformat (must be identical too). With the torque sign not declared, the tool must
say "torque sign reversed?".

The independent estimate, written here from scipy and numpy only: the H1 FRF
``scipy.signal.csd(theta, tau) / scipy.signal.welch(theta)`` (same Welch segment, overlap,
window), then ``numpy.linalg.lstsq`` of ``K + j w B - w^2 I`` on the same band, with
(a) the tool's weighting rebuilt by hand (1/|H| averaged geometrically over the bins 3-6
away) and (b) the textbook 1/|H| of each bin. Prints a Markdown table and writes
bench/results/reklab.json (fitted parameters only).

    python3 bench/bench_reklab.py [PATH/experimental_data.mat]   (default: ../shared/...)
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import trialformat as tf  # noqa: E402
from estimation.lab import AnalysisOptions, Unit, analyse  # noqa: E402

from benchio import write_results

DATA = ROOT.parent / "shared" / "data" / "reklab-ankle" / "experimental_data.mat"
NAMES = ("z_df", "z_df2", "z_df3", "z_pf", "z_pf2")


def recordings(path=DATA):
    """``{name: (angle [rad], torque as stored [N m], dt [s])}`` of the five nldat objects."""
    from matio import load_from_mat
    d = load_from_mat(str(path))
    out = {}
    for k in NAMES:
        p = d[k].properties
        x = np.asarray(p["dataSet"], dtype=float)
        names = [str(np.asarray(c).ravel()[0]) for c in np.asarray(p["chanNames"]).ravel()]
        dt = float(np.asarray(p["domainIncr"]).ravel()[0])
        out[k] = (x[:, names.index("pos1")], x[:, names.index("tq1")], dt)
    return out


def trial(name, angle, torque, dt, declare_sign=True):
    """A lab-format trial in memory; the reader's sign convention applied by hand."""
    meta = tf.default_metadata(1)
    meta.update(fs=1.0 / dt, n_dof=1, perturbed_dof=1, posture_deg=[0.0],
                source=f"reklab/reklab_public stiffnessID/experimental_data.mat {name}")
    meta["perturbation"] = {"kind": "position"}
    meta["sensors"].update(torque_sampling="instantaneous")
    if declare_sign:
        meta["sensors"]["torque_sign"] = -1
    n = len(angle)
    return tf.Trial(meta=meta, t=np.arange(n) * dt, theta=angle[:, None],
                    tau_h=(-torque if declare_sign else torque)[:, None], name=name)


def independent(angle, tau, fs, band, welch):
    """H1 by scipy and weighted lstsq by numpy (module docstring): {"same", "textbook"}."""
    kw = {"fs": fs, "nperseg": welch["nperseg"], "noverlap": welch["noverlap"],
          "window": welch["window"], "nfft": welch["nfft"], "detrend": "constant"}
    f, gxy = signal.csd(angle, tau, **kw)
    _, gxx = signal.welch(angle, **kw)
    h = gxy / gxx
    sel = (f > band[0]) & (f <= band[1])
    z, w = h[sel], 2 * np.pi * f[sel]
    logm = np.log(np.abs(z))
    same = np.array([1 / np.exp(np.mean([logm[j] for j in range(k - 6, k + 7)
                                         if abs(j - k) > 2 and 0 <= j < z.size]))
                     for k in range(z.size)])
    out = {}
    for label, wt in (("same", same), ("textbook", 1 / np.abs(z))):
        A = np.stack([np.ones_like(w), 1j * w, -w ** 2], axis=1) * wt[:, None]
        K, B, I = np.linalg.lstsq(np.vstack([A.real, A.imag]),
                                  np.concatenate([(z * wt).real, (z * wt).imag]),
                                  rcond=None)[0]
        out[label] = {"K": K, "B": B, "I": I}
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    data = Path(argv[0]) if argv else DATA
    if not data.exists():
        print(f"{data} is absent: bring experimental_data.mat from reklab/reklab_public "
              f"(see its README); nothing measured")
        return 0
    options = AnalysisOptions()
    rows, doc = [], {}
    for name, (angle, torque, dt) in recordings(data).items():
        t = trial(name, angle, torque, dt)
        r1, r2 = analyse(Unit(name, [t], "recording"), options), \
            analyse(Unit(name, [t], "recording"), options)
        same_twice = all(np.array_equal(getattr(r1.fit, p), getattr(r2.fit, p))
                         for p in ("M", "B", "K", "M_ci", "B_ci", "K_ci"))
        with tempfile.TemporaryDirectory() as tmp:
            tf.write_trial(Path(tmp) / name, t)
            back = tf.read_trials(Path(tmp) / f"{name}.csv")[0]
        r3 = analyse(Unit(name, [back], "recording"), options)
        same_csv = all(np.array_equal(getattr(r1.fit, p), getattr(r3.fit, p)) for p in "MBK")
        raw = analyse(Unit(name, [trial(name, angle, torque, dt, declare_sign=False)],
                           "recording"), options)
        sign_found = any(w.startswith("torque sign reversed?") for w in raw.warnings)
        ind = independent(angle, -torque, 1 / dt, r1.band_hz, r1.welch)
        p = {q: (float(getattr(r1.fit, q)[0, 0]), float(getattr(r1.fit, f"{q}_ci")[0, 0]))
             for q in "KBM"}
        rng = {q: [float(v[0][0]) for v in r1.sensitivity["range"][q]] for q in "KBM"}
        doc[name] = {"band_hz": list(r1.band_hz), "band_source": r1.band_source,
                     "K": p["K"], "B": p["B"], "I": p["M"], "r2": float(r1.fit.r2[0, 0]),
                     "range": {"K": rng["K"], "B": rng["B"], "I": rng["M"]},
                     "flags": r1.flags, "identical_twice": same_twice,
                     "identical_via_csv": same_csv, "sign_found_when_undeclared": sign_found,
                     "independent": {k: {q: float(v) for q, v in d.items()}
                                     for k, d in ind.items()},
                     "warnings": r1.warnings}
        rows.append((name, r1, p, rng, ind, same_twice, same_csv, sign_found))
    print("| recording | band [Hz] | K [N m/rad] | B [N m s/rad] | I [kg m^2] | R^2 | K, B, I "
          "over bands/weightings | independent, same weights: K, B, I | independent, "
          "1/abs(H): K, B, I | flags | same twice / via CSV / sign found |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r, p, rng, ind, s2, sc, sf in rows:
        a, b = ind["same"], ind["textbook"]
        print(f"| {name} | {r.band_hz[0]:.2f}-{r.band_hz[1]:.1f} | {p['K'][0]:.1f} ± "
              f"{p['K'][1]:.1f} | {p['B'][0]:.3f} ± {p['B'][1]:.3f} | {p['M'][0]:.4f} ± "
              f"{p['M'][1]:.4f} | {r.fit.r2[0, 0]:.3f} | {rng['K'][0]:.0f}...{rng['K'][1]:.0f}, "
              f"{rng['B'][0]:.2f}...{rng['B'][1]:.2f}, {rng['M'][0]:.4f}...{rng['M'][1]:.4f} | "
              f"{a['K']:.1f}, {a['B']:.3f}, {a['I']:.4f} | {b['K']:.1f}, {b['B']:.3f}, "
              f"{b['I']:.4f} | {', '.join(r.flags) or '-'} | {'yes' if s2 else 'NO'} / "
              f"{'yes' if sc else 'NO'} / {'yes' if sf else 'NO'} |")
    write_results("reklab", doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
