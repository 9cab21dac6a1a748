"""``python3 -m labsim --kind KIND --seed S --out FOLDER``: write one simulated recording.

Options: ``--name`` (default ``KIND_sS``), ``--representation`` (default csv17; see
labsim.write; ``mixed`` for a set), ``--duration``, ``--fs``, ``--n-dof``, ``--reflex``,
``--truth-fs``; ``--count N`` writes a set (N recordings of each of the comma-separated
kinds, labsim.write_set); ``--list`` prints the kinds and representations. Prints the
files written and the recording's main truth.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv=None) -> int:
    from . import KINDS, REPRESENTATIONS, draw, simulate, write
    ap = argparse.ArgumentParser(prog="python3 -m labsim", description=__doc__.split("\n")[0])
    ap.add_argument("--kind", default="nominal", help="a kind of labsim.draw (KIND+reflex "
                    "adds a stretch reflex); --list shows them")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draw and recording")
    ap.add_argument("--out", help="folder to write into (created)")
    ap.add_argument("--name", help="trial name (default KIND_sSEED)")
    ap.add_argument("--representation", default="csv17", help="how the file is stored")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds (default 60)")
    ap.add_argument("--fs", type=float, default=1000.0, help="sampling rate [Hz]")
    ap.add_argument("--n-dof", type=int, default=1, choices=(1, 2))
    ap.add_argument("--reflex", action="store_true", help="add a stretch reflex")
    ap.add_argument("--truth-fs", type=float, default=100.0,
                    help="rate of the truth file's arrays [Hz] (0: every sample)")
    ap.add_argument("--count", type=int, default=0,
                    help="write a set: COUNT recordings of each kind in --kind (comma "
                         "separated), with a manifest (labsim.write_set)")
    ap.add_argument("--named", action="store_true",
                    help="a set's files named KIND_NNN (default: blind rec_NNNN)")
    ap.add_argument("--list", action="store_true", help="print kinds and representations")
    args = ap.parse_args(argv)
    if args.list:
        print("kinds:", ", ".join(KINDS), "(each also KIND+reflex)")
        print("representations:", ", ".join(REPRESENTATIONS))
        return 0
    if not args.out:
        ap.error("--out FOLDER is required")
    if args.count:
        return _set(args)
    try:
        spec = draw(args.kind, np.random.default_rng(args.seed), n_dof=args.n_dof,
                    reflex=True if args.reflex else None, duration_s=args.duration,
                    fs=args.fs)
        t0 = time.perf_counter()
        rec = simulate(spec)
        took = time.perf_counter() - t0
        name = args.name or f"{args.kind.replace('+', '_')}_s{args.seed}"
        paths = write(rec, args.out, name, args.representation,
                      truth_fs=None if args.truth_fs == 0 else args.truth_fs)
    except (ValueError, TypeError, OSError) as exc:
        print(f"labsim: error: {exc}", file=sys.stderr)
        return 2
    tr = rec.truth
    print(f"simulated {spec.duration_s:g} s at {spec.fs:g} Hz in {took:.2f} s; wrote "
          + ", ".join(str(p) for p in paths.values() if p))
    print(f"truth: K {tr['nominal']['K']}, B {tr['nominal']['B']}, I {tr['nominal']['I']} "
          f"(at t = 0); varies: {', '.join(tr['varies']) or 'nothing'}; effects: "
          + ", ".join(e["name"] for e in tr["effects"]))
    return 0


def _progress(i, n, name):
    print(f"[{i}/{n}] {name}", flush=True)


def _set(args) -> int:
    from . import write_set
    kinds = [k for k in args.kind.split(",") if k]
    t0 = time.perf_counter()
    try:
        entries = write_set(args.out, kinds, args.count, seed=args.seed,
                            representation=args.representation, n_dof=args.n_dof,
                            duration_s=args.duration, fs=args.fs,
                            truth_fs=None if args.truth_fs == 0 else args.truth_fs,
                            blind=not args.named, progress=_progress)
    except (ValueError, TypeError, OSError) as exc:
        print(f"labsim: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(entries)} recordings to {args.out} in {time.perf_counter() - t0:.1f} s "
          f"(manifest _labsim_set.truth.json)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
