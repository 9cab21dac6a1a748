"""Command-line subcommands of the estimation package: ``estimate`` and ``figures``.

``register(subparsers)`` adds them to the project's CLI (orchestrator/cli.py);
``python -m estimation`` runs them on their own. Both take the analysis the user sets
(method, band, Welch segment, overlap, window, each correction) and work for any number
of joints; ``figures`` writes the lab report (FRF tables, Bode plots, parameters) or, for
this project's simulated grid, the paper's figures.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import trialformat as tf
from trialformat.cliargs import MAX_FFT, number

# Only names here: numpy, scipy and the estimation modules load in the handlers
# (``estimate`` never loads matplotlib), so that --help prints at once.
from .names import METHODS, PAPER, RECOMMENDED, WEIGHTINGS
from .numbers import distinct

TRUTHS = ("none", "table1", "reference-3dof")
#: --reflex-* search ranges: option, ReflexOptions field, unit, largest value, default
#: (estimation.reflex.ReflexOptions; kept here so that --help loads no numpy), example
REFLEX_RANGES = (("--reflex-delay-ms", "delay_ms", "ms", 1000.0, (10.0, 120.0), "10 250"),
                 ("--reflex-cutoff-hz", "cutoff_hz", "Hz", 1000.0, (0.5, 20.0), "0.5 40"),
                 ("--reflex-damping", "damping", "-", 100.0, (0.3, 2.0), "0.2 3"))


def _analysis_arguments(p, truth_default="none") -> None:
    g = p.add_argument_group("analysis (docs/estimation.md; defaults from the data)")
    g.add_argument("--method", choices=("auto",) + METHODS, default="auto",
                   help="auto: full (T P^-1) for one-joint trials or position trials with "
                        "a recorded reference, closed_loop for all-joints trials, direct "
                        "(angle to torque) for position trials without a reference")
    g.add_argument("--band", nargs=2, type=number("--band", 0, 1e6, "0 15", lo_open=False),
                   metavar=("LO", "HI"),
                   help="fit band [Hz] (default: 0 to the declared perturbation.cutoff_hz, "
                        "else from the data: where the perturbation has power and the "
                        "coherence is >= 0.9)")
    g.add_argument("--nperseg", type=number("--nperseg", 2, MAX_FFT, 8192, integer=True,
                                            lo_open=False),
                   default=8192, help="Welch segment [samples]")
    g.add_argument("--noverlap", type=number("--noverlap", 0, MAX_FFT, 6144, integer=True,
                                             lo_open=False), help="Welch overlap [samples] (default 3/4 "
                                                 "of the segment)")
    g.add_argument("--nfft", type=number("--nfft", 2, MAX_FFT, 8192, integer=True,
                                         lo_open=False), help="FFT length [samples] (default: the segment)")
    g.add_argument("--window", default="hann", type=window_name,
                   help="Welch window, a scipy.signal.get_window name without parameters: "
                        + ", ".join(WINDOW_EXAMPLES) + " (default hann; the leakage "
                        "correction needs hann)")
    g.add_argument("--weighting", choices=WEIGHTINGS, default="smoothed",
                   help="bin weights of the M, B, K fit, from the data, solved once: "
                        "smoothed (1/|Z| of the neighbouring bins, relative error; "
                        "default), coherence (1/std from the coherence, Bendat & Piersol), "
                        "relative (1/|Zhat| of the bin), none; model: 1/|Zfit| of a first "
                        "fit (two passes)")
    g.add_argument("--segments", type=int, default=None,
                   help="time segments of each recording fitted apart to detect a "
                        "time-varying impedance (0: no check; default 4, fewer with a "
                        "warning where a recording is too short; more than a recording "
                        "allows is refused, naming the largest that works)")
    g.add_argument("--sampling-correction", choices=("auto", "on", "off"), default="auto",
                   help="half-sample delay of the inertial term for left-limit torque "
                        "sampling; auto: only for trials declaring sensors.torque_sampling "
                        "= left_limit (or simulated by this project)")
    g.add_argument("--leakage-correction", choices=("auto", "on", "off"), default="auto",
                   help="model the Hann window's leakage in the fit (auto: where possible)")
    g.add_argument("--raw", action="store_true", help="both corrections off")
    g.add_argument("--reflex", action="store_true",
                   help="also fit intrinsic K, B, I + a reflex pathway (delayed velocity, "
                        "half-wave rectified, 2nd-order low-pass) to each one-joint trial "
                        "in the time domain (estimation.reflex; docs/estimation.md)")
    for opt, attr, unit, hi, default, ex in REFLEX_RANGES:
        g.add_argument(opt, nargs=2, metavar=("LO", "HI"), default=None,
                       type=number(opt, 0, hi, ex, unit=unit),
                       help=f"with --reflex: search range of the reflex {attr} [{unit}] "
                            f"(default {default[0]:g} {default[1]:g})")
    g.add_argument("--torque-sign", type=int, choices=(1, -1), default=None,
                   help="-1: the recordings' torque has the opposite sign to the angle's "
                        "convention (as metadata sensors.torque_sign, which it overrides: "
                        "for files you cannot add a sidecar to)")
    g.add_argument("--scheduling", metavar="NAME", default=None,
                   help="the scheduling variable the impedance changes with: an extra "
                        "column or nldat variable (sv), time, angle or angle[j] (the slow "
                        "part of theta[j]); as metadata 'scheduling', which it overrides "
                        "(default: the declared one, an nldat 'sv', or the slow angle of a "
                        "joint that moves; docs/estimation.md)")
    g.add_argument("--track", choices=("auto", "segments", "none"), default="auto",
                   help="piecewise-constant K, B, I over time of one-joint trials "
                        "(segments, change times refined on the samples; results.json "
                        "time_segments, figures segments_LABEL.png/.csv): auto where the "
                        "time-variation test finds a step or switching change, segments "
                        "always (e.g. beside --scheduling time's smooth fit), none "
                        "(docs/estimation.md)")
    g.add_argument("--pool", action="store_true",
                   help="average the spectra of unlabelled recordings of the same set-up "
                        "(by default each is estimated alone)")
    g.add_argument("--truth", choices=TRUTHS + (("auto",) if truth_default == "auto" else ()),
                   default=truth_default,
                   help="known answer of simulated trials: Table I (2 joints) or "
                        "reference-3dof.md; none for lab data"
                        + ("; auto: for the paper kind table1 (2 joints) or "
                           "reference-3dof (3 joints), else none" if truth_default == "auto"
                           else ""))


#: Windows named in --window's help and refusal (all scipy.signal.get_window names that
#: need no parameter; tests check each).
WINDOW_EXAMPLES = ("hann", "hamming", "blackman", "blackmanharris", "flattop", "boxcar",
                   "tukey")


def window_name(text: str) -> str:
    """argparse ``type`` of ``--window``: a name scipy.signal.get_window accepts alone;
    otherwise an ArgumentTypeError naming valid ones (argparse adds "argument --window")."""
    if text == "hann":  # the default: no scipy needed
        return text
    from scipy import signal
    try:
        signal.get_window(text, 16)
    except (ValueError, TypeError) as exc:
        needs = "must have parameters" in str(exc)
        why = ("needs parameters, which the command line cannot pass" if needs
               else "is not a scipy.signal window name")
        raise argparse.ArgumentTypeError(
            f"{text!r} {why}; use one of {', '.join(WINDOW_EXAMPLES)} (e.g. --window "
            f"hamming)") from None
    return text


def register(subparsers) -> None:
    """Add ``estimate`` and ``figures`` to an argparse subparsers object."""
    p = subparsers.add_parser("estimate", help="estimate the joint impedance from trials",
                              description="Estimate Z and fit M, B, K per recording or "
                                          "condition from a folder or files (.csv+.json "
                                          "or .mat), for any number of joints.")
    p.add_argument("source", nargs="+", help="folder of trials, or trial files")
    _analysis_arguments(p)
    p.add_argument("--json", type=Path, help="write the results to this JSON file")
    p.set_defaults(func=run_estimate)

    p = subparsers.add_parser("figures", help="lab report, or the paper figures of a grid",
                              description="Lab report (per recording/condition: FRF CSV and "
                                          "JSON, Bode plot with coherence and fit, M, B, K "
                                          "table) or the paper's Figs. 2-4 and tables.")
    p.add_argument("folders", type=Path, nargs="+", help="folders of trials")
    p.add_argument("--out", type=Path, required=True, help="report folder")
    p.add_argument("--kind", choices=("auto", "lab", "paper"), default="auto",
                   help="auto: paper for this project's simulated 2-joint grid, else lab")
    _analysis_arguments(p, truth_default="auto")
    p.add_argument("--fig-variant", default=RECOMMENDED,
                   help=f"paper kind: main variant of Figs. 2-4 (default {RECOMMENDED})")
    p.add_argument("--compare", default=PAPER,
                   help=f"paper kind: variant drawn beside it (default {PAPER}; 'none')")
    p.set_defaults(func=run_figures)


def _reflex_options(args):
    """``--reflex`` and its ``--reflex-*`` ranges: False, True (the defaults) or a
    ReflexOptions. A range without --reflex, or LO >= HI, is refused naming the option."""
    given = {attr: tuple(getattr(args, attr_of(opt)))
             for opt, attr, *_ in REFLEX_RANGES if getattr(args, attr_of(opt), None)}
    reflex = getattr(args, "reflex", False)
    for opt, attr, *_, ex in REFLEX_RANGES:
        if attr in given:
            lo, hi = given[attr]
            if not reflex:
                raise ValueError(f"{opt} sets a search range of the reflex fit: add --reflex")
            if not lo < hi:
                raise ValueError(f"{opt} {lo:g} {hi:g}: LO must be below HI (e.g. {opt} {ex})")
    if not (reflex and given):
        return reflex
    from .reflex import ReflexOptions
    opts = ReflexOptions(**given)
    opts.check()
    return opts


def attr_of(option: str) -> str:
    """argparse's attribute name of ``option``."""
    return option.lstrip("-").replace("-", "_")


def options_from(args):
    from .lab import AnalysisOptions
    options = AnalysisOptions(
        method=args.method, band_hz=tuple(args.band) if args.band else None,
        nperseg=args.nperseg, noverlap=args.noverlap, nfft=args.nfft, window=args.window,
        sampling_correction="off" if args.raw else args.sampling_correction,
        leakage_correction="off" if args.raw else args.leakage_correction, pool=args.pool,
        weighting=args.weighting, segments=args.segments,
        reflex=_reflex_options(args), track=getattr(args, "track", "auto"))
    options.check()
    return options


def _truth(name, n):
    if name == "table1":
        if n != 2:
            raise ValueError(f"--truth table1 is a 2-joint arm; these trials have {n} joints")
        return tf.reference.arm_matrices()
    if name == "reference-3dof":
        if n != 3:
            raise ValueError(f"--truth reference-3dof is a 3-joint arm; these trials have "
                             f"{n} joints")
        from .synthetic import ARM_3DOF
        return ARM_3DOF
    return None


def _read(sources, options, torque_sign=None, scheduling=None, failures=None):
    """Read the trials; the readers' warnings (keys filled from the reference, an unknown
    format) go to stderr as one plain line each, not as Python warnings with source lines.
    ``torque_sign`` (+-1, ``--torque-sign``) replaces the sign the metadata declare;
    ``scheduling`` (``--scheduling NAME``) the declared scheduling variable (refused,
    SchedulingError, where a trial has no usable variable of that name). With a
    ``failures`` list, recordings shorter than one Welch segment among longer ones are
    refused alone (appended as ``(label, message)``, left out of the trials returned);
    without, or when every recording is short, they are refused (:func:`_check_lengths`)."""
    import trialformat as tf
    sources = [Path(s) for s in sources]
    trials = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for s in sources:
            got = tf.read_trials(s, min_samples=2)  # the segment: _check_lengths
            for t in got:
                t.source_arg = s
            trials += got
    _unique_names(trials)
    refused = _check_lengths(trials, options, alone=failures is not None)
    if refused:
        failures += refused
        trials = [t for t in trials if t.n_samples >= options.nperseg]
    if torque_sign is not None:
        for t in trials:
            _declare_torque_sign(t, torque_sign)
    if scheduling is not None:
        from trialformat.scheduling import request
        for t in trials:
            request(t, scheduling)
    from trialformat.cliargs import reader_notes
    for line in reader_notes(caught):
        print(line, file=sys.stderr)
    return trials


def _check_lengths(trials, options, alone: bool = False) -> list:
    """Refuse recordings shorter than one Welch segment (``--nperseg``), naming each and a
    segment that works: the largest power of two giving MIN_AVERAGES (8) averages at the
    chosen overlap (estimator.nperseg_for, as the few-averages warning suggests).

    With ``alone``, when some recordings are long enough, each short one is refused
    alone: returned as ``(label, message)``, its message advising to estimate it by
    itself with that segment (a smaller --nperseg would change every recording's
    analysis); else raised (TrialFormatError). An empty list when none is short."""
    short = [t for t in trials if t.n_samples < options.nperseg]
    if not short:
        return []
    if not alone or len(short) == len(trials):
        raise _short_error(short, options)
    return [(f"{t.name} (from {t.source_arg})", str(_short_error([t], options, alone=True)))
            for t in short]


def _short_error(short, options, alone: bool = False):
    """The refusal of recordings ``short`` (fewer samples than one Welch segment)."""
    from .estimator import MIN_AVERAGES, nperseg_for
    from .spectral import WelchOptions
    w = options.welch()
    n = min(t.n_samples for t in short)
    frac = w["noverlap"] / w["nperseg"]
    hint = nperseg_for(n, WelchOptions(nperseg=w["nperseg"], noverlap=w["noverlap"],
                                       nfft=w["nfft"], window=w["window"]))
    extra = ""
    if options.noverlap is not None:
        extra += f" --noverlap {int(frac * hint)}"
    if options.nfft is not None and options.nfft < hint:
        extra += f" --nfft {hint}"
    names = "; ".join(f"{t.name} (from {t.source_arg}): {t.n_samples} samples, "
                      f"{t.n_samples / t.fs:.4g} s" for t in short)
    import numpy as np
    if hint > n or hint >= options.nperseg:  # no segment fits: advice must not loop
        return tf.TrialFormatError(
            f"{names}: too short for any spectral estimate (--nperseg {options.nperseg}; "
            f"the smallest segment is 16 samples, and {MIN_AVERAGES} Welch averages of it "
            f"need about {int(np.ceil(16 * (1 + (MIN_AVERAGES - 1) * (1 - frac))))} "
            f"samples): record longer")
    if alone:  # the others are estimated: a smaller segment for all would change them
        return tf.TrialFormatError(
            f"{names}: fewer than one spectral segment (--nperseg {options.nperseg}): "
            f"refused alone, the other recordings are estimated; to estimate it, give it "
            f"alone with --nperseg {hint}{extra} ({MIN_AVERAGES} Welch averages of {n} "
            f"samples), or record longer")
    return tf.TrialFormatError(
        f"{names}: fewer than one spectral segment (--nperseg {options.nperseg}): use "
        f"--nperseg {hint}{extra} ({MIN_AVERAGES} Welch averages of {n} samples) or "
        f"longer recordings")


def _declare_torque_sign(trial, sign: int) -> None:
    """The trial as if its metadata declared ``sensors.torque_sign = sign``: the reader
    applied the declared sign d (tau_h = raw * d), so tau_h becomes raw * sign."""
    sensors = trial.meta.setdefault("sensors", {})
    declared = sensors.get("torque_sign", 1)
    if declared != sign:
        trial.tau_h = -trial.tau_h
    sensors["torque_sign"] = sign


def _unique_names(trials) -> None:
    """Recordings of the same name from two sources (``a/rec`` and ``b/rec``, or two
    ``.mat`` files holding ``z_pf``) get the source as prefix, ``SOURCE:NAME``, so that
    their results and report files stay apart; the same recording given twice is refused."""
    names = [t.name for t in trials]
    for t in trials:
        if names.count(t.name) > 1:
            t.name = f"{Path(t.source_arg).name}:{t.name}"
    names = [t.name for t in trials]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"recording(s) {twice} given twice (the same file named more than "
                         f"once); give each once")


def lab_results(trials, options, truth_name="none", failures=None):
    """Analyse every recording or condition. With a ``failures`` list, a condition the
    estimator refuses (EstimationError: too few segments, a joint without a trial...) is
    appended to it as ``(label, message)`` and the others go on; without, it raises.
    A recording whose angles look like degrees beside the radians of its set
    (lab.degree_outliers) is refused alone the same way and removed from ``trials``."""
    from .errors import EstimationError
    from .lab import analyse, degree_outliers, estimation_units
    results = []
    # per recording, before a set is pooled: one in degrees among radians is refused
    # alone and left out of ``trials`` (in place: the grouping line then names the rest)
    odd = [o for unit in estimation_units(trials, pool=options.pool)
           for o in degree_outliers(unit)]
    if odd:
        if failures is None:
            raise EstimationError("; ".join(message for _, message in odd))
        failures += [(t.name, message) for t, message in odd]
        trials[:] = [t for t in trials if all(t is not o for o, _ in odd)]
    for unit in estimation_units(trials, pool=options.pool):
        truth = _truth(truth_name, unit.trials[0].n_dof)
        try:
            results.append(analyse(unit, options, truth=truth))
        except EstimationError as exc:
            if failures is None:
                raise
            failures.append((unit.label, str(exc)))
    return results


def grouping_line(trials, options) -> str:
    """The one line saying how the trials were grouped (estimation.grouping.describe)."""
    from .grouping import describe, trial_sets
    return describe(trial_sets(trials, pool=options.pool))


def print_label_note(trials) -> None:
    """One ``note: ...`` line on stderr (as the readers' notes) naming condition labels
    that differ only by case, spaces or a close spelling
    (estimation.grouping.near_duplicate_labels), if any."""
    from .grouping import near_duplicate_labels
    note = near_duplicate_labels(trials)
    if note:
        print(f"note: {note}", file=sys.stderr)


def _report_failures(failures, results) -> int:
    """Print one line per failed condition; exit status 1 when any failed."""
    from .errors import EstimationError
    if failures and not results:  # nothing to write: the refusal itself, one line
        if len(failures) == 1:
            raise EstimationError(failures[0][1])
        raise EstimationError("no condition could be estimated: " + "; ".join(
            f"{label}: {message}" for label, message in failures))
    for label, message in failures:  # a message naming its recording is not prefixed
        prefix = "" if message.startswith(f"{label}: ") else f"{label}: "
        print(f"error: {prefix}{message}", file=sys.stderr)
    return 1 if failures else 0


def run_estimate(args) -> int:
    options = options_from(args)
    if args.json is not None:
        _check_json_out(args.json)
    failures = []  # recordings refused alone, then conditions the estimator refuses
    trials = _read(args.source, options, args.torque_sign, args.scheduling, failures)
    print_scheduling(trials)
    results = lab_results(trials, options, args.truth, failures)
    status = _report_failures(failures, results)
    grouping = grouping_line(trials, options)
    print(grouping)
    print_label_note(trials)
    for r in results:
        print(describe(r, args.torque_sign))
    _reflex_note(results)
    if args.json:
        recorded = recorded_options(options, args)
        doc = [{**r.to_json(), "condition": r.label, "options": recorded,
                "grouping_rule": grouping,
                "compensated": r.corrections["left_limit_sampling"],
                "leakage_removed": r.corrections["window_leakage"]} for r in results]
        args.json.parent.mkdir(parents=True, exist_ok=True)
        tf.atomic_write(args.json, lambda fh: fh.write(json.dumps(doc, indent=1).encode()))
    return status if results else 1


def recorded_options(options, args) -> dict:
    """The analysis options as recorded in ``results.json`` and ``--json``: the
    AnalysisOptions fields and ``torque_sign`` (``--torque-sign``: +-1, or None when the
    metadata's ``sensors.torque_sign`` was used)."""
    from dataclasses import asdict, is_dataclass
    out = dict(options.__dict__)
    if is_dataclass(out.get("reflex")):
        out["reflex"] = asdict(out["reflex"])
    out["torque_sign"] = args.torque_sign
    out["scheduling"] = getattr(args, "scheduling", None)
    return out


def scheduling_lines(trials) -> list:
    """One line per recording that has a scheduling variable (trialformat.scheduling):
    its name, units, source and range, how it was chosen, and whether its range is too
    narrow for a parameter-varying fit; nothing for a stationary recording."""
    from trialformat.scheduling import narrow_range, scheduling_of
    lines = []
    for t in trials:
        s = scheduling_of(t)
        if s is None:
            continue
        how = s.note or f"scheduling variable {s.describe()}"
        why = narrow_range(s)
        if why:
            how += f"; range too narrow for a parameter-varying fit: {why}"
        lines.append(f"{t.name}: {how}")
    return lines


def print_scheduling(trials) -> None:
    """Print :func:`scheduling_lines` (what was read; the parameter-varying estimate
    follows each result, estimation.pvlab). The readers' notes of the default rule go to
    stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lines = scheduling_lines(trials)
    for line in lines:
        print(line)
    from trialformat.cliargs import reader_notes
    for line in reader_notes(caught):
        print(line, file=sys.stderr)


def _check_json_out(path: Path) -> None:
    """Refuse a ``--json`` that would overwrite anything but an earlier ``--json`` results
    file: a folder, a trial (``.csv``, ``.csv.gz``, ``.mat``, its metadata), any other file;
    a path below a file."""
    tf.logs.check_out_parent(path, "--json")
    if path.is_dir():
        raise tf.OutputError(f"--json {path}: is a folder; give a file name "
                             f"(e.g. {path / 'results.json'})")
    if path.is_file():
        try:
            doc = json.loads(path.read_text(encoding="utf-8-sig"))
        except (ValueError, UnicodeDecodeError, OSError):
            doc = None
        if isinstance(doc, dict) and ("n_dof" in doc or str(doc.get("format", "")).startswith(
                "arm-impedance-trial")):
            raise tf.OutputError(f"--json {path}: is a trial's metadata (it would be "
                                 f"replaced by the results); give another file name")
        ours = isinstance(doc, list) and all(
            isinstance(d, dict) and "condition" in d and "method" in d for d in doc)
        if not ours:
            raise tf.OutputError(f"--json {path}: exists and is not an earlier results file "
                                 f"of 'estimate --json' (a trial, its metadata or another "
                                 f"file would be replaced); give a new file name")

def describe(r, torque_sign=None) -> str:
    """Text of one result: set-up line, one line per element, the warnings.
    ``torque_sign`` (``--torque-sign``, +-1) is said in the set-up line when given."""
    from .lab import UNITS, WEIGHTING_TEXT, element_indices, symbol_of as symbol
    c = r.corrections
    sign = ("" if torque_sign is None else
            f"; torque sign {torque_sign:+d} (--torque-sign, over the metadata)")
    lines = [f"{r.label}: method={r.method}, trials={', '.join(r.trials)} ({r.reason}); "
             f"band {r.band_hz[0]:g}-{r.band_hz[1]:g} Hz ({r.band_source}), "
             f"{r.n_segments} segments; "
             f"sampling correction {'on' if c['left_limit_sampling'] else 'off'}, "
             f"leakage correction {'on' if c['window_leakage'] else 'off'}{sign}",
             f"  fit: {WEIGHTING_TEXT[r.weighting]} ({r.weighting})"]
    conf = int(round(100 * r.fit.confidence))
    for i, k in element_indices(r.n_dof):
        e = f"Z{i + 1}{k + 1}" if r.n_dof > 1 else "Z"
        inertia = "M" if r.n_dof > 1 else "I"
        text = (f"  {e}: K={r.fit.K[i, k]:.5g}±{r.fit.K_ci[i, k]:.2g} {UNITS['K']}  "
                f"B={r.fit.B[i, k]:.5g}±{r.fit.B_ci[i, k]:.2g} {UNITS['B']}  "
                f"{inertia}={r.fit.M[i, k]:.5g}±{r.fit.M_ci[i, k]:.2g} {UNITS['M']}  "
                f"R2={r.fit.r2[i, k]:.5f} VAF={r.vaf[i, k]:.3f}% "
                f"coh={r.coherence_band[i, k]:.3f}")
        if r.errors_pct is not None:
            text += "  err K/B/M=" + "/".join(f"{r.errors_pct[p][i, k]:+.2f}"
                                              for p in "KBM") + "%"
        lines.append(text)
    lines.append(f"  (± : {conf} % confidence intervals)")
    if r.sensitivity:
        nv = len(r.sensitivity["variants"])
        for i, k in element_indices(r.n_dof):
            e = f"Z{i + 1}{k + 1}" if r.n_dof > 1 else "Z"
            rng = r.sensitivity["range"]
            lines.append(f"  {e} over {nv} band/weighting choices: " + "  ".join(
                f"{symbol(p, r.n_dof)} " + "...".join(distinct([rng[p][0][i][k],
                                                                rng[p][1][i][k]]))
                for p in "KBM"))
    lines += [f"  warning: {w}" for w in r.warnings]
    lines += [x.describe() for x in (r.reflex or [])]
    from .pvlab import describe_varying
    lines += describe_varying(getattr(r, "varying", None) or [])
    from .segmentlab import describe_segments
    lines += describe_segments(getattr(r, "time_segments", None) or [])
    k = k_by_model(r)
    if k:
        lines.append(k)
    return "\n".join(lines)


def k_by_model(r) -> str | None:
    """One line naming every stiffness a one-joint result printed, by the model that gave
    it (the FRF fit, the parallel cascade's pathways, the parameter-varying fit, the time
    segments), when more than one model gave one; None otherwise. They answer different
    questions (issue 21: five unlabelled K values on the moving ankle)."""
    if r.n_dof != 1:
        return None
    import numpy as np  # not at the top: `armimp --help` loads no numpy
    u = "N m/rad"
    parts = [f"FRF fit {r.band_hz[0]:.3g}-{r.band_hz[1]:.3g} Hz {r.fit.K[0, 0]:.4g}"
             f"±{r.fit.K_ci[0, 0]:.2g}"]
    for x in r.reflex or []:
        parts.append(f"time-domain K-B-I alone {x.intrinsic_only['K']:.4g}")
        parts.append(f"parallel cascade's intrinsic pathway {x.values['K']:.4g}"
                     f"±{x.ci['K']:.2g}")
    for f in getattr(r, "varying", None) or []:
        v, lo, hi = f.invariant["K"]
        parts.append(f"parameter-varying fit's time-invariant order 0 {v:.4g} "
                     f"[{lo:.4g}, {hi:.4g}], over {f.scheduling} "
                     f"{np.min(f.values['K']):.4g}..{np.max(f.values['K']):.4g}")
    for sgm in getattr(r, "time_segments", None) or []:
        ks = np.asarray(sgm.values["K"], float)
        if ks.size > 1:
            parts.append(f"time segments {ks.min():.4g}..{ks.max():.4g}")
    if len(parts) < 2:
        return None
    return (f"  K by model ({u}; each answers another question, and a limb that changes "
            f"has no single K): " + "; ".join(parts))


def reflex_note(results) -> str | None:
    """One line for the results ``--reflex`` does not apply to (several joints): which,
    and that their K, B, M result is the usual one; None when it applied everywhere."""
    joints = [r for r in results if any(s["kind"] == "joints" for s in r.reflex_not_fitted)]
    if not joints:
        return None
    which = ", ".join(f"{r.label} ({r.n_dof} joints)" for r in joints)
    return (f"note: --reflex fits the one-joint parallel-cascade model; not applied to "
            f"{which}: their result above is the usual M, B, K fit")


def _reflex_note(results) -> None:
    note = reflex_note(results)
    if note:
        print(note, file=sys.stderr)


def _paper_kind(trials) -> bool:
    return all(t.n_dof == 2 and str(t.meta.get("source", "")).startswith(
        ("simulated: orchestrator", "estimation.synthetic: linear")) for t in trials)


def run_figures(args) -> int:
    options = options_from(args)
    # refused before any reading: a report replaces only its own earlier report
    tf.logs.check_report_out(args.out, args.folders, kinds=("lab", "paper"))
    refused = []  # recordings refused alone (shorter than one Welch segment)
    trials = _read(args.folders, options, args.torque_sign, args.scheduling, refused)
    print_scheduling(trials)
    kind, status = args.kind, 0
    if kind == "auto":
        kind = "paper" if _paper_kind(trials) else "lab"
    if kind == "paper" and refused:  # the paper's report reads the folders itself
        raise tf.TrialFormatError("; ".join(message for _, message in refused))
    if kind == "paper":
        if options.reflex:
            print("note: --reflex applies to the lab report (--kind lab) of one-joint "
                  "recordings; the paper's figures do not use it", file=sys.stderr)
        truth = args.truth
        if truth == "auto":  # the known answer of this project's simulated arms
            n = max(t.n_dof for t in trials)
            truth = {2: "table1", 3: "reference-3dof"}.get(n, "none")
        compare = None if args.compare.lower() == "none" else args.compare
        from .report import make_report
        result = make_report(args.folders, args.out, truth=truth, variant=args.fig_variant,
                             compare=compare)
        files = result["files"]
        for k in result["skipped"]:  # per condition and method, the report goes on
            print(f"skipped: {k['condition']} ({k['tuning']}) {k['method']}: {k['reason']}",
                  file=sys.stderr)
    else:
        truth = "none" if args.truth == "auto" else args.truth
        from .labreport import write_lab_report
        failures = refused
        results = lab_results(trials, options, truth, failures)
        status = _report_failures(failures, results)
        grouping = grouping_line(trials, options)
        files = write_lab_report(results, args.out, options={
            **recorded_options(options, args), "truth": truth}, grouping=grouping)
        print(grouping)
        print_label_note(trials)
        for r in results:
            print(describe(r, args.torque_sign))
        _reflex_note(results)
    for f in files:
        print(f)
    return status


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m estimation")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError, KeyError) as exc:
        print(f"python -m estimation {args.command}: error: "
              f"{tf.csvtable.printable(str(exc), lines=True)}", file=sys.stderr)
        return 1
