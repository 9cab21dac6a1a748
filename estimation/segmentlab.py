"""The lab estimator's hook for a switching impedance: piecewise-constant K, B, I of a
one-joint recording (estimation.segmentfit.segment_track) reported beside the
time-invariant estimate.

When it runs (``AnalysisOptions.track``, ``--track``):

- ``auto`` (default): on each one-joint trial whose time-variation test
  (estimation.timevarying, the ``time_variation`` entry of results.json) found a change
  shaped as a ``step``, ``steps``, ``switching`` (a piecewise-constant impedance) or
  ``modulated`` (:data:`AUTO_SHAPES`: a square wave seen through the test's 1 s windows
  can look like one); a drift is the smooth parameter-varying fit's (``--scheduling
  time``), which the user can ask for beside the segments;
- ``segments``: on every one-joint trial, whatever the test found (a stationary trial
  gives one segment); a trial with several joints, or too short, gets a warning naming why;
- ``none``: never.

Each track's ``trigger`` says why it ran: the test's finding (``time-variation test:
switching change``) when there is one, else ``requested (--track segments)``.

results.json (and ``--json``) get ``time_segments``: ``{"trial", "trigger",
"change_times_s", "segments": [{"start_s", "stop_s", "K": [v, lo, hi], "B": [...],
"I": [...]}], "confidence", "window_s", "warnings"}`` (a second trial's under
``"others"``); ``figures`` draws ``segments_LABEL.png`` and ``segments_LABEL.csv``.
"""

from __future__ import annotations

import numpy as np

#: the time-variation test's shapes that get segments in auto mode (timevarying.classify):
#: the piecewise-constant ones, and "modulated": the 1 s window test calls a square-wave
#: K of 2 s levels on a 14 s labsim record "modulated" (its windows astride the switches
#: blur the steps); a drift is the smooth fit's (--scheduling time)
AUTO_SHAPES = ("step", "steps", "switching", "modulated")
TRACKS = ("auto", "segments", "none")
PARAMS = ("K", "B", "I")
UNITS = {"K": "N m/rad", "B": "N m s/rad", "I": "kg m^2"}
NAMES = {"K": "stiffness", "B": "damping", "I": "inertia"}


def _step_found(name, time_variation) -> str | None:
    """The shape (one of :data:`AUTO_SHAPES`) of the change the time-variation entries
    (JSON dicts, timevarying.of_trials) of trial ``name`` found; None when none."""
    for d in time_variation or []:
        if d.get("trial") == name and d.get("time_varying") and d.get("shape") in AUTO_SHAPES:
            return d["shape"]
    return None


def segments_of_trials(trials, track="auto", time_variation=None) -> tuple[list, list]:
    """``(tracks, warnings)``: a :class:`estimation.segmentfit.SegmentTrack` (with its
    ``trial`` and ``trigger`` set) per trial the mode ``track`` selects (module
    docstring), and one warning per selected trial it could not be done for (several
    joints, too short, non-finite data)."""
    if track not in TRACKS:
        raise ValueError(f"--track must be one of {', '.join(TRACKS)}, got {track!r}")
    if track == "none":
        return [], []
    from .segmentfit import segment_track
    out, notes = [], []
    for t in trials:
        auto = _step_found(t.name, time_variation)
        if track == "auto" and not auto:
            continue
        if t.n_dof != 1:
            notes.append(f"time-segment track not done for {t.name}: it is for one joint; "
                         f"{t.name!r} has {t.n_dof}")
            continue
        try:
            s = segment_track(t.theta[:, 0], t.tau_h[:, 0], t.fs)
        except (ValueError, np.linalg.LinAlgError) as exc:
            notes.append(f"time-segment track not done for {t.name} "
                         f"({t.n_samples / t.fs:.3g} s at {t.fs:g} Hz): {exc}")
            continue
        s.trial = t.name
        s.trigger = (f"time-variation test: {auto} change" if auto
                     else "requested (--track segments)")
        out.append(s)
    return out, notes


def track_json(s) -> dict:
    """The ``time_segments`` document of one SegmentTrack: each parameter as
    ``[value, lo, hi]`` (95 % interval, SI units)."""
    e = s.edges_s
    segs = []
    for j in range(len(e) - 1):
        row = {"start_s": float(e[j]), "stop_s": float(e[j + 1])}
        for p in PARAMS:
            v, h = float(s.values[p][j]), float(s.ci[p][j])
            row[p] = [v, v - h, v + h]
        segs.append(row)
    return {"trial": getattr(s, "trial", ""), "trigger": getattr(s, "trigger", ""),
            "change_times_s": [float(x) for x in s.change_s], "segments": segs,
            "confidence": 0.95, "window_s": s.window_s, "units": dict(UNITS),
            "warnings": list(s.warnings)}


def segments_json(tracks) -> dict | None:
    """results.json's ``time_segments``: the first track's document, the others under
    ``"others"``; None without a track."""
    if not tracks:
        return None
    docs = [track_json(s) for s in tracks]
    out = docs[0]
    if len(docs) > 1:
        out["others"] = docs[1:]
    return out


def describe_segments(tracks) -> list:
    """One short line per track: the number of changes and K's levels."""
    lines = []
    for s in tracks:
        n = s.change_s.size
        at = ", ".join(f"{x:.2f}" for x in s.change_s[:6]) + (" ..." if n > 6 else "")
        k = "  ".join(f"{v:.4g}±{h:.2g}" for v, h in zip(s.values["K"][:6], s.ci["K"][:6]))
        more = " ..." if len(s.values["K"]) > 6 else ""
        lines.append(f"  time segments ({getattr(s, 'trial', '')}): {n} change"
                     f"{'' if n == 1 else 's'}" + (f" at {at} s" if n else "")
                     + f"; K per segment {k}{more} {UNITS['K']} (95 %; results.json "
                       f"time_segments)")
    return lines


def plot_segments(s, path) -> None:
    """K(t), B(t), I(t) as step functions with their 95 % bands, the change times
    dashed: one panel each, saved to ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(6.4, 6.9), sharex=True)
    e = s.edges_s
    for ax, p in zip(axes, PARAMS):
        v, h = np.asarray(s.values[p]), np.asarray(s.ci[p])
        vv = np.r_[v, v[-1]]
        ax.fill_between(e, np.r_[v - h, v[-1] - h[-1]], np.r_[v + h, v[-1] + h[-1]],
                        step="post", color="tab:blue", alpha=0.25, label="95 % interval")
        ax.step(e, vv, where="post", color="tab:blue", label="segment value")
        for c in s.change_s:
            ax.axvline(c, color="0.4", ls="--", lw=0.7)
        ax.set_ylabel(f"{p} [{UNITS[p]}]")
        ax.set_title(NAMES[p], fontsize=9, loc="left")
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(fontsize=7, loc="best")
    n = s.change_s.size
    fig.suptitle(f"{getattr(s, 'trial', '')}: piecewise-constant impedance, {n} change"
                 f"{'' if n == 1 else 's'} ({getattr(s, 'trigger', '')})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_segment_files(result, folder, stem) -> list:
    """``segments_STEM.png`` (:func:`plot_segments`) and ``segments_STEM.csv`` (one row
    per segment: start_s, stop_s, then each parameter's value, lo, hi) for each track of
    ``result`` (LabResult ``time_segments``); a second trial's files get ``_TRIAL``
    appended. Returns the paths written."""
    import csv
    from pathlib import Path
    paths = []
    for k, s in enumerate(getattr(result, "time_segments", None) or []):
        name = f"segments_{stem}" + (f"_{s.trial}" if k else "")
        png = Path(folder) / f"{name}.png"
        plot_segments(s, png)
        table = Path(folder) / f"{name}.csv"
        doc = track_json(s)
        with open(table, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["start_s", "stop_s"] + [f"{p}{x} [{UNITS[p]}]" for p in PARAMS
                                                for x in ("", "_lo", "_hi")])
            for row in doc["segments"]:
                w.writerow([repr(row["start_s"]), repr(row["stop_s"])]
                           + [repr(x) for p in PARAMS for x in row[p]])
        paths += [png, table]
    return paths
