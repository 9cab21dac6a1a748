"""Intrinsic + reflex identification (estimation.reflex): known answers and the ankle data.

1. Known answers: estimation.synthetic_reflex recordings (60 s, 1 kHz, torque noise 5 %
   of its std) with reflex delays 30, 45 and 60 ms; the errors of every parameter.
2. The five measured ankle recordings of ../shared/data/reklab-ankle/experimental_data.mat
   (when present; skipped otherwise), read as NLID nldat objects from a copy of the file
   in a temporary folder with a sidecar declaring ``torque_sign: -1`` (the data's README:
   the torque is recorded with the opposite sign). Each recording is fitted twice from
   the .mat (same numbers every run?) and once from lab-format CSV written to the
   temporary folder (same numbers from CSV?), and compared with the plain K-B-I fit of the
   lab estimator (``armimp estimate``, default analysis).

Prints markdown tables and writes bench/results/reflex.json (summary figures only, no
data). Run from the repository root: ``python3 bench/bench_reflex.py`` (about 2 min of
CPU).
"""

import json
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import trialformat as tf  # noqa: E402
from estimation import lab  # noqa: E402
from estimation.reflex import PARAMS, fit_reflex, fit_reflex_trial  # noqa: E402
from estimation.synthetic_reflex import parallel_cascade  # noqa: E402

DATA = next((p for p in (ROOT.parent / "shared", ROOT.parents[1] / "shared")
             if (p / "data" / "reklab-ankle" / "experimental_data.mat").is_file()), None)


def known_answers():
    rows = []
    for delay in (0.030, 0.045, 0.060):
        sim = parallel_cascade(delay_s=delay, duration_s=60.0, seed=int(1000 * delay))
        t0 = time.process_time()
        r = fit_reflex(sim["theta"], sim["tau"], 1000.0)
        cpu = time.process_time() - t0
        err = {p: (r.values[p] - sim["truth"][p]) if p == "delay_ms" else
               100 * (r.values[p] / sim["truth"][p] - 1) for p in PARAMS}
        rows.append({"delay_ms_true": 1e3 * delay, "values": r.values, "ci": r.ci,
                     "errors (pct; delay in ms)": err, "vaf_pct": r.vaf_pct,
                     "cpu_s": cpu})
        print(f"delay {1e3 * delay:.0f} ms: " + ", ".join(
            f"{p} {err[p]:+.2f}{' ms' if p == 'delay_ms' else ' %'}" for p in PARAMS)
            + f"; CPU {cpu:.1f} s")
    return rows


def ankle():
    if DATA is None:
        print("ankle recordings: skipped (../shared/data/reklab-ankle absent)")
        return None
    src = DATA / "data" / "reklab-ankle" / "experimental_data.mat"
    tmp = Path(tempfile.mkdtemp(prefix="bench_reflex_"))
    try:
        shutil.copy(src, tmp / "experimental_data.mat")
        (tmp / "experimental_data.json").write_text(json.dumps({"torque_sign": -1}))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            trials = tf.read_trials(tmp / "experimental_data.mat")
            csv_dir = tmp / "csv"
            for t in trials:
                tf.write_trial(csv_dir / t.name, t)
            from_csv = {t.name: t for t in tf.read_trials(csv_dir)}
        out = []
        for t in trials:
            t0 = time.process_time()
            a = fit_reflex_trial(t)
            cpu = time.process_time() - t0
            b = fit_reflex_trial(t)
            c = fit_reflex_trial(from_csv[t.name])
            plain = lab.analyse(lab.Unit(t.name, [t], "single recording"))
            out.append({"trial": t.name, "rectify": a.rectify, "values": a.values,
                        "ci": a.ci, "vaf_pct": a.vaf_pct, "intrinsic_only": a.intrinsic_only,
                        "warnings": a.warnings,
                        "same_every_run": a.values == b.values and a.ci == b.ci,
                        "same_from_csv": a.values == c.values and a.ci == c.ci,
                        "plain_fit": {"method": plain.method, "band_hz": list(plain.band_hz),
                                      "K": float(plain.fit.K[0, 0]),
                                      "K_ci": float(plain.fit.K_ci[0, 0]),
                                      "B": float(plain.fit.B[0, 0]),
                                      "B_ci": float(plain.fit.B_ci[0, 0]),
                                      "I": float(plain.fit.M[0, 0]),
                                      "I_ci": float(plain.fit.M_ci[0, 0]),
                                      "R2": float(plain.fit.r2[0, 0])},
                        "cpu_s": cpu})
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def table(rows):
    head = ("| trial | K [N m/rad] | B [N m s/rad] | I [kg m^2] | G [N m s/rad] | delay [ms] | "
            "low-pass [Hz] | damping | VAF I / R / total [%] | K-B-I alone (time): K, VAF | "
            "plain fit (lab estimator): K, B, I, R^2 | same every run / from CSV |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        v, c, p = r["values"], r["ci"], r["plain_fit"]
        cells = [f"{r['trial']} ({r['rectify']})"] + [f"{v[k]:.4g} ± {c[k]:.2g}"
                                                      for k in PARAMS]
        cells += [f"{r['vaf_pct']['intrinsic']:.1f} / {r['vaf_pct']['reflex']:.1f} / "
                  f"{r['vaf_pct']['total']:.1f}",
                  f"{r['intrinsic_only']['K']:.4g}, {r['vaf_pct']['intrinsic_only']:.1f} %",
                  f"{p['K']:.4g} ± {p['K_ci']:.2g}, {p['B']:.3g}, {p['I']:.3g}, "
                  f"{p['R2']:.3f}",
                  f"{'yes' if r['same_every_run'] else 'NO'} / "
                  f"{'yes' if r['same_from_csv'] else 'NO'}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    doc = {"known_answers": known_answers()}
    rows = ankle()
    if rows is not None:
        doc["ankle"] = rows
        print(table(rows))
        for r in rows:
            for w in r["warnings"]:
                print(f"- {r['trial']}: {w}")
    out = ROOT / "bench" / "results" / "reflex.json"
    tf.atomic_write(out, lambda fh: fh.write(json.dumps(doc, indent=1).encode()))
    print(out.relative_to(ROOT))


if __name__ == "__main__":
    main()
