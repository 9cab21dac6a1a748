"""The position fit's noise floor (issue 21 item 1): detection of broadband non-linear
torque and false alarms on nominal sets, with the Welch non-coherent floor of
diagnosis.limbfit against the white floor read above the band (the floor before).

labsim (the independent simulator, docs/labsim.md) draws one-joint recordings without a
recorded servo reference (as bench_time_state.py: with one the servo's own dynamics give
every set a gap).

* Detection: footplate friction (tanh or LuGre), backlash and contact clipping, each
  scaled so that the non-linear torque (the recorded torque minus that of the same
  recording without the effect: same seed, same noise) carries a target fraction of the
  torque energy in the analysis band (0.3-30 Hz); the scaling is one secant step from
  labsim's draw, and the fraction *reached* is what the table shows. Detected = the
  nominal gap is significant (any verdict but "no significant gap").
* False alarms: nominal sets with white sensor noise, with 1/f noise only, with mains hum
  only (labsim's coloured-noise channel split in two), and with a voluntary torque of
  10-50 % of the perturbation torque's RMS. A false alarm = a significant nominal gap.

    nice -n 10 python3 bench/bench_noise_floor.py              # 4 seeds, fractions 0.1 0.25, 40 s
    nice -n 10 python3 bench/bench_noise_floor.py --seeds 2 --fractions 0.1

Writes bench/results/noise_floor.json and prints the table (rates with 95 % Wilson
intervals).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import labsim  # noqa: E402
from diagnosis import limbfit as lf  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchio import wilson, write_results  # noqa: E402

NONLINEAR = ("friction_tanh", "friction_lugre", "backlash", "contact_clipping")
NOMINAL = ("white", "pink", "hum", "voluntary")
FLOORS = ("coherence", "white")


def band_energy(x, fs, lo=0.3, hi=30.0):
    """Welch energy of x (N,) in [lo, hi] Hz [units^2]."""
    f, p = signal.welch(x - np.mean(x), fs=fs, nperseg=int(2 * fs))
    sel = (f >= lo) & (f <= hi)
    return float(np.sum(p[sel]) * (f[1] - f[0]))


def nominal_spec(kind, seed, duration_s):
    rng = np.random.default_rng(1000 + seed)
    if kind in ("pink", "hum"):
        spec = labsim.draw("nominal_coloured_noise", rng, duration_s=duration_s)
        ch = spec.sensors.tau
        if kind == "pink":
            ch.hum_std = 0.0
        else:
            ch.pink_std = 0.0
            spec.sensors.theta.pink_std = 0.0
        if kind == "pink":
            spec.sensors.theta.hum_std = 0.0
        spec.record_reference = False
        return spec
    spec = labsim.draw("voluntary" if kind == "voluntary" else "nominal", rng,
                       duration_s=duration_s)
    spec.record_reference = False
    return spec


def _set_strength(spec, kind, s):
    fp = spec.footplate
    if kind.startswith("friction"):
        fp.friction_fraction = s
    elif kind == "backlash":
        fp.backlash_rad = s
    else:
        fp.contact_limit_nm = spec.limb.background_torque_nm + s


def nonlinear_spec(kind, seed, duration_s):
    """(spec with the effect, spec without it, the strength parameter's first value)."""
    rng = np.random.default_rng(2000 + seed)
    base = {"friction_tanh": "footplate_friction", "friction_lugre": "footplate_friction",
            "backlash": "backlash", "contact_clipping": "contact_clipping"}[kind]
    spec = labsim.draw(base, rng, duration_s=duration_s)
    spec.record_reference = False
    if kind.startswith("friction"):
        spec.footplate.friction = kind.split("_")[1]
        s0 = spec.footplate.friction_fraction
    elif kind == "backlash":
        s0 = spec.footplate.backlash_rad
    else:
        s0 = spec.footplate.contact_limit_nm - spec.limb.background_torque_nm
    plain = copy.deepcopy(spec)
    plain.footplate = None  # the background torque of contact_clipping stays
    return spec, plain, s0


def _unexplained(trial, limb):
    """Recorded torque minus the true linear limb's torque of the recorded angle (N,)."""
    from diagnosis import limb as lm
    K, B, I = (np.atleast_2d(np.asarray(getattr(limb, k), float)) for k in ("K", "B", "I"))
    theta, tau = trial.signal("theta"), trial.signal("tau_h")
    lin = lm.limb_torque(theta, trial.fs, lm.LimbModel(K, B, I))
    # the file's torque sign (labsim draws it): the one the limb's torque agrees with
    sign = 1.0 if np.sum(tau * lin) >= 0 else -1.0
    return (sign * tau - lin)[:, 0]


def fraction(rec, plain_rec, spec):
    """Band energy of the non-linear torque over the recorded torque's: the torque the
    true linear limb does not explain from the recorded angle, less the same of the
    recording without the effect (noise, discretisation)."""
    fs = rec.trial.fs
    tau = rec.trial.signal("tau_h")[:, 0]
    e = band_energy(_unexplained(rec.trial, spec.limb), fs)
    e0 = band_energy(_unexplained(plain_rec.trial, spec.limb), fs)
    return (e - e0) / band_energy(tau, fs)


def decide(trial):
    """{floor: (significant, gap excess, threshold, source)} of one trial."""
    out = {}
    for floor in FLOORS:
        # the floor before, with the threshold before (no model tolerance)
        cfg = (lf.FitConfig(noise_floor=floor) if floor == "coherence" else
               lf.FitConfig(noise_floor=floor, model_tolerance=0.0))
        preps = lf.prepare([lf.PositionRecord.from_trial(trial)], cfg)
        g = lf.fit_nominal(preps, cfg)["gaps"]["all"]
        thr = g.threshold(cfg)
        out[floor] = {"significant": bool(g.significant(cfg)), "excess": g.excess, "se": g.se,
                      "threshold": thr, "floor": g.floor, "source": g.source.split(":")[0]}
    return out


def run_nonlinear(kind, seed, target, duration_s, plain_cache):
    spec, plain, s0 = nonlinear_spec(kind, seed, duration_s)
    key = (kind, seed)
    if key not in plain_cache:
        plain_cache[key] = labsim.simulate(plain)
    prec = plain_cache[key]
    s, rec, phi = s0, None, None
    for _ in range(4):  # secant steps in log strength against log fraction
        _set_strength(spec, kind, s)
        try:
            rec = labsim.simulate(spec)
        except labsim.SimulationError as exc:
            return {"kind": kind, "seed": seed, "target": target, "error": str(exc)[:120]}
        phi = fraction(rec, prec, spec)
        if 0.8 * target <= phi <= 1.4 * target:
            break
        # friction, backlash: energy ~ strength^2; clipping: the margin shrinks the energy
        power = 2.0 if kind != "contact_clipping" else -2.0
        s = s * (target / max(phi, 1e-9)) ** (1.0 / power)
    return {"kind": kind, "seed": seed, "target": target, "fraction": phi, "strength": s,
            **decide(rec.trial)}


def run_nominal(kind, seed, duration_s):
    rec = labsim.simulate(nominal_spec(kind, seed, duration_s))
    return {"kind": kind, "seed": seed, **decide(rec.trial)}


def table(rows, nominal_rows):
    lines = ["| set | target fraction | fraction reached (median) | n | detected, coherence "
             "floor [95 % CI] | detected, white floor (before) [95 % CI] |",
             "|---|---|---|---|---|---|"]
    summary = {"detection": [], "false_alarms": []}
    for kind in NONLINEAR:
        for target in sorted({r["target"] for r in rows}):
            sel = [r for r in rows if r["kind"] == kind and r["target"] == target
                   and "error" not in r]
            if not sel:
                continue
            n = len(sel)
            cells = []
            entry = {"kind": kind, "target": target, "n": n,
                     "fraction_median": float(np.median([r["fraction"] for r in sel]))}
            for floor in FLOORS:
                k = sum(r[floor]["significant"] for r in sel)
                ci = wilson(k, n)
                entry[floor] = {"detected": k, "rate": k / n, "wilson95": ci}
                cells.append(f"{k}/{n} [{ci[0]:.2f}, {ci[1]:.2f}]")
            summary["detection"].append(entry)
            lines.append(f"| {kind} | {target:g} | {entry['fraction_median']:.3g} | {n} | "
                         + " | ".join(cells) + " |")
    lines += ["", "| nominal set | n | false alarms, coherence floor [95 % CI] | "
              "false alarms, white floor (before) [95 % CI] |", "|---|---|---|---|"]
    for kind in NOMINAL:
        sel = [r for r in nominal_rows if r["kind"] == kind]
        if not sel:
            continue
        n = len(sel)
        entry, cells = {"kind": kind, "n": n}, []
        for floor in FLOORS:
            k = sum(r[floor]["significant"] for r in sel)
            ci = wilson(k, n)
            entry[floor] = {"false_alarms": k, "rate": k / n, "wilson95": ci}
            cells.append(f"{k}/{n} [{ci[0]:.2f}, {ci[1]:.2f}]")
        summary["false_alarms"].append(entry)
        lines.append(f"| {kind} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines), summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.1, 0.25])
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--only", choices=("nonlinear", "nominal"), default=None)
    args = ap.parse_args(argv)
    t0 = time.time()
    rows, nominal_rows, cache = [], [], {}
    if args.only != "nonlinear":
        for kind in NOMINAL:
            for seed in range(args.seeds):
                row = run_nominal(kind, seed, args.duration)
                nominal_rows.append(row)
                print(kind, seed, {f: (row[f]["significant"], f"{row[f]['excess']:.3g}",
                                       f"{row[f]['threshold']:.3g}") for f in FLOORS},
                      flush=True)
    if args.only != "nominal":
        for kind in NONLINEAR:
            for seed in range(args.seeds):
                for target in args.fractions:
                    row = run_nonlinear(kind, seed, target, args.duration, cache)
                    rows.append(row)
                    print(kind, seed, target, row.get("error") or
                          (f"{row['fraction']:.3g}",
                           {f: (row[f]["significant"], f"{row[f]['excess']:.3g}",
                                f"{row[f]['threshold']:.3g}") for f in FLOORS}), flush=True)
    text, summary = table(rows, nominal_rows)
    print(text)
    write_results("noise_floor", {"command": "python3 bench/bench_noise_floor.py "
                                  + " ".join(sys.argv[1:] if argv is None else argv),
                                  "seeds": args.seeds, "fractions": args.fractions,
                                  "duration_s": args.duration, "summary": summary,
                                  "table_markdown": text, "nonlinear": rows,
                                  "nominal": nominal_rows,
                                  "elapsed_s": time.time() - t0})
    return 0


if __name__ == "__main__":
    sys.exit(main())
