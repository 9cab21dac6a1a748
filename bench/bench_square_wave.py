"""A van de Ruit-style benchmark: a square-wave stiffness tracked over Monte-Carlo runs.

Truth (labsim, the project's independent simulator): one joint on a PD position servo
(80 Hz, damping 0.8), Gaussian perturbation flat to 40 Hz of RMS 0.02 rad, 1 kHz, 44 s;
K(t) a square wave between 0.5x and 2x a nominal 80 N m/rad (40 and 160 N m/rad),
period 4 s (2 s at each level), the first switch at 0.37 s (not on a window edge of the
trackers), B = 1.2 N m s/rad, I = 0.015 kg m^2 constant. Sensor noise: white noise on
the torque at an output SNR of ``--snr-db`` (15 dB default, the SNR of Cavallo et al.
2022's simulation): variance 10^(-SNR/10) times the noise-free recorded torque's. Each
run draws a new perturbation and a new noise (seeds ``[seed, run]``); the square wave is
the same in every run (as in van de Ruit et al. 2021), so bias and random error are
per-time statistics over the runs.

Trackers of K(t), each read on a 200 Hz grid over the 40 s between the 2 s edges every
tracker leaves out:

- ``pv_chebyshev``: estimation.varying.fit_varying, scheduling = time (``armimp estimate
  --scheduling time``), Chebyshev order chosen by held-out error (up to 12);
- ``window_1s`` / ``window_0.25s``: estimation.timevarying.track, K per window (1 s, the
  default; 0.25 s), held over the window (a step function);
- ``blocks_1s``: the change-point blocks of estimation.timevarying.time_variation
  (default settings), each block's mean K held over it;
- ``segment_fit``: estimation.segmentfit.segment_track (change points of the 0.25 s
  window test, refined on the samples, K-B-I least squares per segment).

Metrics (van de Ruit et al. 2021's list): VAF of the tracked K(t) against the truth [%]
per run (mean, 5th percentile over runs); bias: the mean over runs of the error at each
time, averaged over time (signed) and as RMS over time, % of the mean K; random error:
the SD over runs at each time, RMS over time, % of the mean K (both also over the times
more than 0.1 s from a switch: the levels' own errors, the switches' timing apart); rise time: 10-90 % of
each switch (searched within a quarter period either side), of the mean-over-runs track
(which includes the runs' timing jitter) and the median over runs and switches of each
run's own; CPU s per run (process time of the tracker alone, the simulation apart).

Coverage (``--coverage``: the segment-wise fit alone, the other trackers not run): over
every segment of every run whose fitted span (the segment less ``GUARD_S`` at an inner
end) holds no true switch, the fraction whose 95 % half-width covers the truth (K: the
true K's mean over that span; B, I constant), for the reported half-width (``ci``: the
batch means where a segment has 3 sub-blocks, else the window noise) and for each of its
two sources: ``ci_window`` (the window test's
noise sigma scaled by sqrt(window / span)) and ``ci_batch`` (batch means of 0.25 s
sub-block fits). Writes bench/results/square_wave_coverage_SNRdB.json (40 runs took
6 min wall on the shared machine, 20 at 5 dB 2 min).

Run from the repository root: ``nice python3 bench/bench_square_wave.py [--runs 100]``
(2 worker processes; 100 runs took 18 min wall on the shared 2-core machine, mostly
the simulation; ``--runs 4`` for a quick check). Prints a markdown
table and writes bench/results/square_wave.json.
"""

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from benchio import write_results  # noqa: E402

K_NOM, PERIOD_S, PHASE_S, DURATION_S, FS = 80.0, 4.0, 0.37, 44.0, 1000.0
EDGE_S, GRID_HZ = 2.0, 200.0
#: "levels only" figures leave out the times this close to a switch [s]
AWAY_S = 0.1
METHODS = ("pv_chebyshev", "window_1s", "window_0.25s", "blocks_1s", "segment_fit")
LABELS = {"pv_chebyshev": "parameter-varying, Chebyshev in time (varying.py)",
          "window_1s": "windowed LS, 1 s (timevarying.track)",
          "window_0.25s": "windowed LS, 0.25 s (timevarying.track)",
          "blocks_1s": "change-point blocks, 1 s windows (time_variation)",
          "segment_fit": "segment-wise fit, refined change points (segmentfit.py)"}

#: published figures, as found (docs: the search of the literature, see the report)
PUBLISHED = [
    {"method": "kernel-based regression, locally periodic kernel",
     "source": "Cavallo, Schouten & Lataire, 'Locally periodic kernel-based regression to "
               "identify time-varying ankle impedance during locomotion: a simulation "
               "study' (TU Delft research portal abstract)",
     "set_up": "simulated gait, 10 cycles of 1.4 s, output SNR 15 dB, Monte Carlo; smooth "
               "periodic impedance profiles (not a square wave)",
     "vaf_pct": "~99.9 (of the noiseless simulated *torque output*, not of K(t))",
     "parameter_error_pct": "1.33-4.06 (mean normalised RMSE of the K, B, I profiles)",
     "bias_pct": None, "random_pct": None, "rise_time": None},
    {"method": "ensemble; short data segment; basis impulse response function; ensemble "
               "spectral; kernel-based regression",
     "source": "van de Ruit, Mugge, Cavallo, Lataire, Ludvig & Schouten, 'Quantitative "
               "comparison of time-varying system identification methods to describe "
               "human joint impedance', Annu Rev Control 52:91-107, 2021",
     "set_up": "square-wave stiffness, 100 simulation trials; metrics VAF, bias, random "
               "and total error, rise time",
     "vaf_pct": None, "parameter_error_pct": None, "bias_pct": None, "random_pct": None,
     "rise_time": None,
     "note": "the per-method figures were not in the abstracts the search found; not "
             "quoted (not invented)"},
]


def spec_for(run, seed):
    import labsim
    rng = np.random.default_rng([seed, run])
    return labsim.RecordingSpec(
        duration_s=DURATION_S, fs=FS, seed=int(rng.integers(2 ** 31)),
        perturbation=labsim.Perturbation(kind="noise", amplitude_rad=0.02,
                                         band_hz=[0.0, 40.0]),
        servo=labsim.Servo(kind="pd", f_hz=80.0, damping=0.8),
        limb=labsim.Limb(K=0.5 * K_NOM, B=1.2, I=0.015,
                         K_var=labsim.Variation(time="switching", ratio=4.0,
                                                period_s=PERIOD_S, phase_s=PHASE_S)))


def _held(t_grid, centres, values, width):
    """A per-window estimate held over its window (a step function on t_grid)."""
    starts = np.asarray(centres) - width / 2
    k = np.clip(np.searchsorted(starts, t_grid, side="right") - 1, 0, len(values) - 1)
    return np.asarray(values)[k]


def track_all(theta, tau, fs, t_grid):
    """{method: (K on t_grid, cpu s, extra)}."""
    from estimation.segmentfit import segment_track
    from estimation.timevarying import time_variation, track
    from estimation.varying import fit_varying
    out = {}
    t = np.arange(theta.size) / fs
    c = time.process_time()
    pv = fit_varying(theta, tau, t, fs, name="time", units="s", is_time=True)
    out["pv_chebyshev"] = (pv.at(t_grid)["K"], time.process_time() - c,
                           {"order": pv.order, "heldout_vaf_pct": pv.heldout_vaf_pct})
    for name, w in (("window_1s", 1.0), ("window_0.25s", 0.25)):
        c = time.process_time()
        tr = track(theta, tau, fs, window_s=w)
        out[name] = (_held(t_grid, tr["t"], tr["K"], tr["window_s"]),
                     time.process_time() - c, {})
    c = time.process_time()
    tv = time_variation(theta, tau, fs)
    starts = np.array([b.t_s[0] for b in tv.blocks])
    kb = np.array([b.values["K"] for b in tv.blocks])
    k = np.clip(np.searchsorted(starts, t_grid, side="right") - 1, 0, len(kb) - 1)
    out["blocks_1s"] = (kb[k], time.process_time() - c,
                        {"n_blocks": len(tv.blocks), "shape": tv.shape})
    c = time.process_time()
    sg = segment_track(theta, tau, fs)
    out["segment_fit"] = (sg.at(t_grid)["K"], time.process_time() - c,
                          {"n_changes": int(sg.change_s.size),
                           "change_s": [float(x) for x in sg.change_s]})
    return out


def one_run(args):
    run, seed, snr_db = args
    import labsim
    rec = labsim.simulate(spec_for(run, seed))
    theta = rec.trial.theta[:, 0]
    tau = rec.trial.tau_h[:, 0]
    rng = np.random.default_rng([seed, run, 1])
    noise_sd = float(np.std(tau)) * 10 ** (-snr_db / 20)
    tau_n = tau + noise_sd * rng.standard_normal(tau.size)
    t_grid = grid()
    tracks = track_all(theta, tau_n, rec.trial.fs, t_grid)
    K_true = np.asarray(rec.truth["arrays"]["K"], float).ravel()
    t = np.asarray(rec.truth["arrays"]["t"], float).ravel()
    return {"run": run, "K_true": np.interp(t_grid, t, K_true),
            "switch_s": t[1:][np.diff(K_true) != 0].tolist(),
            "tracks": {m: v[0].astype(np.float32) for m, v in tracks.items()},
            "cpu_s": {m: v[1] for m, v in tracks.items()},
            "extra": {m: v[2] for m, v in tracks.items()}}


def coverage_run(args):
    """One run of ``--coverage``: per segment of the segment-wise fit, its values,
    half-widths (ci, ci_window, ci_batch) and the truth over its fitted span."""
    run, seed, snr_db = args
    import labsim
    from estimation.segmentfit import GUARD_S, segment_track
    rec = labsim.simulate(spec_for(run, seed))
    tau = rec.trial.tau_h[:, 0]
    rng = np.random.default_rng([seed, run, 1])
    tau_n = tau + float(np.std(tau)) * 10 ** (-snr_db / 20) * rng.standard_normal(tau.size)
    c = time.process_time()
    sg = segment_track(rec.trial.theta[:, 0], tau_n, rec.trial.fs)
    cpu = time.process_time() - c
    a = rec.truth["arrays"]
    t = np.asarray(a["t"], float).ravel()
    truth = {p: np.asarray(a[p], float).ravel() if p in a else None for p in ("K", "B", "I")}
    const = {"B": 1.2, "I": 0.015}
    switches = t[1:][np.diff(truth["K"]) != 0]
    e = sg.edges_s
    segs = []
    for j in range(len(e) - 1):
        lo = e[j] + (GUARD_S if j else 0.0)
        hi = e[j + 1] - (GUARD_S if j + 2 < len(e) else 0.0)
        m = (t >= lo) & (t < hi)
        clean = not np.any((switches > lo) & (switches < hi))
        row = {"start_s": float(e[j]), "stop_s": float(e[j + 1]), "clean": bool(clean)}
        for p in ("K", "B", "I"):
            tv = truth[p]
            row[p] = {"value": float(sg.values[p][j]),
                      "truth": float(np.mean(tv[m])) if tv is not None and m.any()
                      else const.get(p, float("nan")),
                      **{k: float(getattr(sg, k)[p][j]) for k in ("ci", "ci_window",
                                                                  "ci_batch")}}
        segs.append(row)
    return {"run": run, "segments": segs, "n_changes": int(sg.change_s.size),
            "cpu_s": cpu}


def coverage_summary(rows) -> dict:
    """Coverage [%] per parameter and half-width kind over the clean segments; median
    half-widths; the RMS of the errors over the median half-width / 1.96."""
    segs = [s for r in rows for s in r["segments"]]
    clean = [s for s in segs if s["clean"]]
    out = {"segments": len(segs), "clean_segments": len(clean), "params": {}}
    for p in ("K", "B", "I"):
        err = np.array([s[p]["value"] - s[p]["truth"] for s in clean])
        d = {"rms_error": float(np.sqrt(np.mean(err ** 2))) if err.size else None}
        for k in ("ci", "ci_window", "ci_batch"):
            h = np.array([s[p][k] for s in clean])
            ok = np.isfinite(h)
            d[k] = {"coverage_pct": float(100 * np.mean(np.abs(err[ok]) <= h[ok]))
                    if ok.any() else None,
                    "median_half_width": float(np.median(h[ok])) if ok.any() else None,
                    "n": int(ok.sum())}
        out["params"][p] = d
    return out


def coverage_table(cov, runs, snr_db) -> str:
    lines = [f"Coverage of the segment-wise fit's 95 % half-widths: {runs} runs, "
             f"{cov['clean_segments']} segments without a true switch (of "
             f"{cov['segments']}), SNR {snr_db:g} dB", "",
             "| parameter | RMS error | coverage % ci (median hw) | ci_window | ci_batch |",
             "|---|---|---|---|---|"]
    for p, d in cov["params"].items():
        cells = [f"{d[k]['coverage_pct']:.1f} ({d[k]['median_half_width']:.3g})"
                 if d[k]["coverage_pct"] is not None else "-"
                 for k in ("ci", "ci_window", "ci_batch")]
        lines.append(f"| {p} | {d['rms_error']:.3g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def grid():
    return np.arange(EDGE_S, DURATION_S - EDGE_S, 1.0 / GRID_HZ)


def vaf(est, true):
    return float(100 * (1 - np.var(est - true) / np.var(true)))


def rise_times(t, k, switches, true):
    """10-90 % rise (fall) time [s] of each switch of ``k`` (on ``t``); NaN where the
    track does not reach 90 % within a quarter period after the switch."""
    out = []
    q = PERIOD_S / 4
    for ts in switches:
        before = float(np.interp(ts - q, t, true))
        after = float(np.interp(ts + q, t, true))
        if ts - q < t[0] or ts + q > t[-1]:
            continue
        m = (t >= ts - q) & (t <= ts + q)
        frac = (k[m] - before) / (after - before)
        tt = t[m]
        i10 = np.flatnonzero(frac >= 0.1)
        if not i10.size:
            out.append(np.nan)
            continue
        i90 = np.flatnonzero(frac[i10[0]:] >= 0.9)
        out.append(float(tt[i10[0] + i90[0]] - tt[i10[0]]) if i90.size else np.nan)
    return np.array(out)


def summarise(rows):
    t = grid()
    true = rows[0]["K_true"]
    switches = rows[0]["switch_s"]
    mean_k = float(np.mean(true))
    res = {}
    for m in METHODS:
        est = np.stack([r["tracks"][m] for r in rows]).astype(float)
        err = est - true[None, :]
        vafs = np.array([vaf(e, true) for e in est])
        bias_t = err.mean(0)
        rand_t = est.std(0, ddof=1) if len(rows) > 1 else np.zeros_like(true)
        rise_mean = rise_times(t, est.mean(0), switches, true)
        away = np.min(np.abs(t[:, None] - np.array(switches)[None, :]), axis=1) > AWAY_S
        per_run = np.concatenate([rise_times(t, e, switches, true) for e in est])
        res[m] = {
            "label": LABELS[m],
            "vaf_pct_mean": float(vafs.mean()), "vaf_pct_p5": float(np.percentile(vafs, 5)),
            "vaf_pct_of_mean_track": vaf(est.mean(0), true),
            "bias_pct_mean": float(100 * bias_t.mean() / mean_k),
            "bias_pct_rms": float(100 * np.sqrt(np.mean(bias_t ** 2)) / mean_k),
            "random_pct_rms": float(100 * np.sqrt(np.mean(rand_t ** 2)) / mean_k),
            "total_pct_rms": float(100 * np.sqrt(np.mean(err ** 2)) / mean_k),
            "levels_only": {  # the times more than AWAY_S from a switch
                "bias_pct_rms": float(100 * np.sqrt(np.mean(bias_t[away] ** 2)) / mean_k),
                "random_pct_rms": float(100 * np.sqrt(np.mean(rand_t[away] ** 2)) / mean_k)},
            "rise_time_ms_mean_track": float(1e3 * np.nanmedian(rise_mean))
            if np.any(np.isfinite(rise_mean)) else None,
            "rise_not_reached_mean_track": int(np.sum(~np.isfinite(rise_mean))),
            "rise_time_ms_per_run_median": float(1e3 * np.nanmedian(per_run))
            if np.any(np.isfinite(per_run)) else None,
            "rise_not_reached_per_run_frac": float(np.mean(~np.isfinite(per_run))),
            "cpu_s_per_run": float(np.mean([r["cpu_s"][m] for r in rows])),
            "vaf_pct_runs": [float(v) for v in vafs]}
    orders = [r["extra"]["pv_chebyshev"]["order"] for r in rows]
    res["pv_chebyshev"]["orders_chosen"] = {str(o): orders.count(o) for o in sorted(set(orders))}
    res["pv_chebyshev"]["heldout_vaf_pct_runs"] = [r["extra"]["pv_chebyshev"]["heldout_vaf_pct"]
                                                  for r in rows]
    nch = [r["extra"]["segment_fit"]["n_changes"] for r in rows]
    n_true = len([s for s in switches if EDGE_S < s < DURATION_S - EDGE_S])
    res["segment_fit"]["n_changes_found"] = {str(o): nch.count(o) for o in sorted(set(nch))}
    res["segment_fit"]["n_changes_true"] = n_true
    errs = []
    for r in rows:
        cs = np.array(r["extra"]["segment_fit"]["change_s"])
        for s in switches:
            if EDGE_S < s < DURATION_S - EDGE_S and cs.size:
                errs.append(float(cs[np.argmin(np.abs(cs - s))] - s))
    errs = np.array(errs)
    res["segment_fit"]["change_time_error_ms"] = {
        "mean": float(1e3 * errs.mean()), "sd": float(1e3 * errs.std()),
        "median_abs": float(1e3 * np.median(np.abs(errs))),
        "p95_abs": float(1e3 * np.percentile(np.abs(errs), 95))}
    blocks = [r["extra"]["blocks_1s"]["n_blocks"] for r in rows]
    res["blocks_1s"]["n_blocks"] = {str(o): blocks.count(o) for o in sorted(set(blocks))}
    return res


def basis_ceilings():
    """VAF [%] of the least-squares best fit of the noise-free square wave (over the
    evaluated 40 s) by fixed bases: the most any estimate in that basis can reach.
    Chebyshev orders (varying.py's basis in time; it tries up to 12) and B-splines of
    degree 0 (a windowed estimate held over its window), 1 and 3 with knots every h s."""
    from scipy.interpolate import make_lsq_spline
    t = grid()
    phase = np.floor((t - PHASE_S) / (0.5 * PERIOD_S))
    K = np.where((t >= PHASE_S) & (np.mod(phase, 2) == 1), 2 * K_NOM, 0.5 * K_NOM)
    u = 2 * (t - t[0]) / (t[-1] - t[0]) - 1
    out = {"chebyshev_order": {}, "bspline": {}}
    for o in (6, 12, 20, 40, 80):
        V = np.polynomial.chebyshev.chebvander(u, o)
        out["chebyshev_order"][str(o)] = vaf(V @ np.linalg.lstsq(V, K, rcond=None)[0], K)
    for h in (1.0, 0.5, 0.25):
        for k in (0, 1, 3):
            inner = np.arange(t[0] + h, t[-1] - h / 2, h)
            knots = np.r_[[t[0]] * (k + 1), inner, [t[-1] + 1e-9] * (k + 1)]
            out["bspline"][f"h={h:g} s, degree {k}"] = vaf(make_lsq_spline(t, K, knots, k=k)(t), K)
    return out


def table(res, runs, snr_db):
    def f(x, fmt):
        return "-" if x is None else format(x, fmt)
    lines = [f"Square-wave K(t), 40 <-> 160 N m/rad, period {PERIOD_S:g} s, {runs} runs, "
             f"output SNR {snr_db:g} dB (labsim, PD servo, noise perturbation to 40 Hz)", "",
             "| tracker | VAF % (mean; 5th pct) | bias % (mean; RMS) | random % (RMS SD) "
             "| total % (RMS) | bias; random % >0.1 s from a switch "
             "| rise 10-90 % ms (mean track; per run) | CPU s/run |",
             "|---|---|---|---|---|---|---|---|"]
    for m in METHODS:
        r = res[m]
        miss = r["rise_not_reached_per_run_frac"]
        miss = f" ({100 * miss:.0f} % not reached)" if miss else ""
        lines.append(
            f"| {r['label']} | {r['vaf_pct_mean']:.1f}; {r['vaf_pct_p5']:.1f} | "
            f"{r['bias_pct_mean']:+.2f}; {r['bias_pct_rms']:.1f} | {r['random_pct_rms']:.1f} | "
            f"{r['total_pct_rms']:.1f} | {r['levels_only']['bias_pct_rms']:.1f}; "
            f"{r['levels_only']['random_pct_rms']:.1f} | "
            f"{f(r['rise_time_ms_mean_track'], '.0f')}; "
            f"{f(r['rise_time_ms_per_run_median'], '.0f')}{miss} | "
            f"{r['cpu_s_per_run']:.2f} |")
    for p in PUBLISHED:
        cells = [p[k] or "not found" for k in ("vaf_pct", "bias_pct", "random_pct",
                                               "parameter_error_pct", "rise_time")]
        lines.append(f"| published: {p['method']} ({p['source'].split(',')[0]} et al.) | "
                     + " | ".join(cells[:4]) + " | - | " + cells[4] + " | - |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=20)
    ap.add_argument("--snr-db", type=float, default=15.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--coverage", action="store_true",
                    help="the segment-wise fit's 95 %% half-widths' coverage only")
    args = ap.parse_args(argv)
    try:
        from tqdm import tqdm
    except ImportError:  # progress on stderr without tqdm
        def tqdm(it, total=None, **_):
            for i, x in enumerate(it):
                print(f"run {i + 1}/{total}", file=sys.stderr)
                yield x
    t0 = time.time()
    jobs = [(r, args.seed, args.snr_db) for r in range(args.runs)]
    if args.coverage:
        with ProcessPoolExecutor(max_workers=args.workers) as ex:
            rows = list(tqdm(ex.map(coverage_run, jobs), total=len(jobs), desc="coverage"))
        cov = coverage_summary(rows)
        print(coverage_table(cov, args.runs, args.snr_db))
        nch = [r["n_changes"] for r in rows]
        write_results(f"square_wave_coverage_{args.snr_db:g}dB", {
            "bench": "square_wave_coverage", "runs": args.runs, "seed": args.seed,
            "snr_db": args.snr_db, "wall_s": time.time() - t0, "coverage": cov,
            "n_changes_found": {str(o): nch.count(o) for o in sorted(set(nch))},
            "cpu_s_per_run": float(np.mean([r["cpu_s"] for r in rows]))})
        return
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        rows = list(tqdm(ex.map(one_run, jobs), total=len(jobs), desc="square wave"))
    res = summarise(rows)
    print(table(res, args.runs, args.snr_db))
    ceil = basis_ceilings()
    print("\nNoise-free ceiling of fixed bases (VAF % of the best fit of the true K(t)): "
          + "; ".join(f"Chebyshev order {o}: {v:.1f}" for o, v in ceil["chebyshev_order"].items())
          + "; " + "; ".join(f"B-spline {k}: {v:.1f}" for k, v in ceil["bspline"].items()))
    doc = {"bench": "square_wave", "runs": args.runs, "seed": args.seed,
           "snr_db": args.snr_db, "wall_s": time.time() - t0,
           "truth": {"K_low": 0.5 * K_NOM, "K_high": 2 * K_NOM, "period_s": PERIOD_S,
                     "first_switch_s": PHASE_S, "B": 1.2, "I": 0.015,
                     "duration_s": DURATION_S, "fs_hz": FS, "evaluated_s": [EDGE_S,
                                                                            DURATION_S - EDGE_S],
                     "servo": "PD 80 Hz, damping 0.8",
                     "perturbation": "Gaussian, flat to 40 Hz, RMS 0.02 rad",
                     "noise": f"white on the torque, variance 10^(-{args.snr_db:g}/10) "
                              f"of the noise-free torque's"},
           "methods": res, "basis_ceilings_vaf_pct": ceil, "published": PUBLISHED}
    write_results("square_wave", doc)


if __name__ == "__main__":
    main()
