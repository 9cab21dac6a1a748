"""Blind validation of the diagnosis on position-servo experiments (docs/diagnosis.md,
section "The limb and the position-servo catalogue").

Sets of one-joint (ankle-like) and two-joint (arm-like) position-servo trials are made by
truth models: a limb drawn per set, a band-limited random position perturbation whose
amplitude steps between three levels, white encoder and torque-sensor noise, and the
withheld effects of diagnosis.limb drawn from the catalogue's realistic ranges (or an
effect outside the catalogue, diagnosis.outside). Each trial is stored in a storage
representation (diagnosis.representation), with ``NAME.truth.json`` beside it; the
diagnosis reads the trials back through trialformat and never opens a truth file; the
verdicts are scored with diagnosis.validation's scorer (Wilson 95 % intervals).

Truth models (documented magnitudes):

* one joint: K ~ U(40, 150) N m/rad, B ~ U(0.4, 1.5) N m s/rad, I ~ U(0.012, 0.03)
  kg m^2 (the human ankle with its foot plate); perturbation std 8 mrad;
* two joints: the reference arm's K_h, B_h, M_h (docs/spec/reference.md) with K scaled
  by U(4, 8) and B by U(2, 4) (an arm co-contracting against a stiff planar robot),
  independent perturbations of std 6 mrad on both joints at once;
* perturbation: Gaussian noise through an 8th-order Butterworth low-pass at 12 Hz,
  amplitude x0.5, x1, x2 in 5 s blocks (random order);
* noise: encoder std U(2e-6, 1e-5) rad, torque std U(0.005, 0.02) N m;
* theta_ref recorded in half the sets (always with servo_bandwidth), else only the
  measured angle.
"""

from __future__ import annotations

import copy
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

from . import catalogue as cat
from . import limb as lm
from . import limbfit as lf
from .outside import POSITION_OUTSIDE, position_outside
from .representation import REPRESENTATIONS, trial_written, write_represented

TRUTH_SUFFIX = ".truth.json"
FS = 1000.0


@dataclass(frozen=True)
class PositionSetSpec:
    """One position-servo validation set (one trial).

    effects : tuple of (name, primary params) withheld; outside : {"name", "params"} or {};
    n_dof : 1 or 2; seed; duration_s; representation; record_ref : theta_ref stored.
    """

    name: str
    effects: tuple = ()
    n_dof: int = 1
    seed: int = 1
    duration_s: float = 30.0
    representation: str = "float64"
    record_ref: bool = False
    outside: dict = field(default_factory=dict)

    def truth(self, limb: lm.LimbModel, noise: dict) -> dict:
        return {"effects": [{"name": n, "params": p} for n, p in self.effects],
                "representation": self.representation, "experiment": "position",
                "n_dof": self.n_dof, "theta_ref_recorded": self.record_ref,
                "limb": {"K": limb.K.tolist(), "B": limb.B.tolist(), "I": limb.I.tolist()},
                "noise": noise,
                **({"outside_catalogue": self.outside} if self.outside else {})}


def draw_limb(rng: np.random.Generator, n_dof: int) -> lm.LimbModel:
    """A truth limb (module docstring)."""
    if n_dof == 1:
        return lm.LimbModel(rng.uniform(40, 150), rng.uniform(0.4, 1.5),
                            rng.uniform(0.012, 0.03))
    if n_dof != 2:
        raise ValueError(f"position validation sets have 1 or 2 joints, not {n_dof}")
    from trialformat import reference as ref
    arm = ref.reference()["human_arm"]
    return lm.LimbModel(np.array(arm["K_h"]) * rng.uniform(4, 8),
                        np.array(arm["B_h"]) * rng.uniform(2, 4),
                        np.array(arm["M_h"]) * rng.uniform(0.8, 1.25))


def perturbation(rng: np.random.Generator, n_samples: int, n_dof: int,
                 fs: float = FS) -> np.ndarray:
    """The position perturbation (n_samples, n_dof) [rad] of the module docstring."""
    sos = signal.butter(8, 12.0, fs=fs, output="sos")
    warm = int(2 * fs)
    x = signal.sosfilt(sos, rng.standard_normal((n_samples + warm, n_dof)), axis=0)[warm:]
    x /= x.std(axis=0)
    block = int(5 * fs)
    n_blocks = -(-n_samples // block)
    levels = np.concatenate([rng.permutation([0.5, 1.0, 2.0])
                             for _ in range(-(-n_blocks // 3))])[:n_blocks]
    amp = np.repeat(levels, block)[:n_samples]
    # smooth 50 ms ramps between levels (a servo is never commanded a step in amplitude)
    k = int(0.05 * fs)
    amp = np.convolve(np.pad(amp, (k, k), mode="edge"), np.ones(2 * k + 1) / (2 * k + 1),
                      mode="valid")
    return (0.008 if n_dof == 1 else 0.006) * x * amp[:, None]


def make_position_trial(spec: PositionSetSpec):
    """(trialformat.Trial, truth dict) of the set's trial."""
    import trialformat as tf
    rng = np.random.default_rng(spec.seed)
    limb = draw_limb(rng, spec.n_dof)
    n_samples = int(round(spec.duration_s * FS))
    ref = perturbation(rng, n_samples, spec.n_dof)
    effects = {name: lm.effect_params(name, cat.expand_effect(name, p, spec.n_dof))
               for name, p in spec.effects}
    theta = lm.servo_angle(ref, FS, effects)
    extra_tau = 0.0
    limb_theta = theta
    if spec.outside:
        limb_theta, extra_tau = position_outside(spec.outside["name"], spec.outside["params"],
                                                 theta, FS)
    tau = lm.limb_torque(limb_theta, FS, limb, effects) + extra_tau
    noise = {"theta_std_rad": float(math.exp(rng.uniform(math.log(2e-6), math.log(1e-5)))),
             "tau_std_nm": float(math.exp(rng.uniform(math.log(0.005), math.log(0.02))))}
    theta_m = theta + noise["theta_std_rad"] * rng.standard_normal(theta.shape)
    tau_m = tau + noise["tau_std_nm"] * rng.standard_normal(tau.shape)
    meta = {"format": tf.FORMAT, "fs": FS, "n_dof": spec.n_dof,
            "perturbed_dof": 1 if spec.n_dof == 1 else None,
            "posture_deg": [0.0] * spec.n_dof,
            "perturbation": {"kind": "position", "seed": int(spec.seed),
                             "std_rad": float(0.008 if spec.n_dof == 1 else 0.006)},
            "sensors": {"torque_sampling": "instantaneous"},
            "source": "diagnosis position validation set (truth withheld)"}
    trial = tf.Trial(meta=meta, t=np.arange(n_samples) / FS, theta=theta_m, tau_h=tau_m,
                     theta_ref=ref if spec.record_ref else None, name=spec.name)
    return trial, spec.truth(limb, noise)


def make_position_set(spec: PositionSetSpec, folder) -> Path:
    """Write the set's trial (in its representation) and truth file; resumable."""
    folder = Path(folder) / spec.name
    folder.mkdir(parents=True, exist_ok=True)
    stem = folder / spec.name
    truth_path = Path(str(stem) + TRUTH_SUFFIX)
    if trial_written(stem) and truth_path.is_file():
        return folder
    trial, truth = make_position_trial(spec)
    _atomic_json(truth_path, truth)
    write_represented(stem, trial, spec.representation)
    return folder


def _atomic_json(path: Path, obj) -> None:
    from .report import _clean
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(_clean(obj), fh, indent=2)
    os.replace(tmp, path)


def draw_position_specs(rng: np.random.Generator, *, n_per_effect: int = 2,
                        n_nominal: int = 4, n_outside: int = 4, duration_s: float = 30.0,
                        representations: tuple | None = None) -> list[PositionSetSpec]:
    """Every position effect ``n_per_effect`` times (joints 1 and 2 in turn), nominal and
    outside sets likewise, representations drawn at random."""
    reps = tuple(representations or REPRESENTATIONS)

    def common(i):
        return {"n_dof": 1 + i % 2, "seed": int(rng.integers(1, 100_000)),
                "duration_s": duration_s,
                "representation": str(reps[int(rng.integers(len(reps)))])}

    specs = []
    from .varying_effects import EFFECTS as varying
    for name in cat.effects_for("position"):
        if name in varying:  # no diagnosis.limb truth: validated on labsim truths
            continue         # (bench/bench_time_state.py)
        effect = cat.get_effect(name)
        for i in range(n_per_effect):
            c = common(i)
            specs.append(PositionSetSpec(f"pos{c['n_dof']}-{name}-{i}",
                                         ((name, _stratified(effect, effect.draw(rng), i,
                                                             n_per_effect)),),
                                         record_ref=(name == "servo_bandwidth" or i % 2 == 1),
                                         **c))
    for i in range(n_nominal):
        c = common(i)
        specs.append(PositionSetSpec(f"pos{c['n_dof']}-nominal-{i}", (),
                                     record_ref=i % 2 == 0, **c))
    for i in range(n_outside):
        name = POSITION_OUTSIDE[i % len(POSITION_OUTSIDE)]
        c = common(i // len(POSITION_OUTSIDE))
        specs.append(PositionSetSpec(f"pos{c['n_dof']}-outside-{name}-{i}", (),
                                     outside={"name": name, "params": draw_outside(rng, name)},
                                     **c))
    return specs


def _stratified(effect, params: dict, i: int, n: int) -> dict:
    """A parameter drawn log-uniformly over a wide magnitude range (``draw_log``: the
    channel delay, 2-40 ms) moved into the i-th of n equal strata of its log range, from
    the same uniform number (no other draw changes): every part of the range is
    exercised, its long end (a 30-40 ms delay, where the first search failed) included,
    whatever the seed."""
    out = dict(params)
    for p in effect.parameters:
        if not p.draw_log or n < 2:
            continue
        lo, hi = p.realistic
        v = out[p.name]
        sign = -1.0 if v < p.off else 1.0
        u = math.log(abs(v - p.off) / lo) / math.log(hi / lo)
        out[p.name] = float(p.off + sign * lo * (hi / lo) ** ((i % n + u) / n))
    return out


#: (delay [s], joints) of the long-channel-delay check (bench --long-delays)
LONG_DELAYS = ((0.030, 1), (-0.035, 1), (0.040, 1), (0.032, 2), (-0.038, 2), (0.036, 1),
               (-0.030, 1), (0.039, 2))


def long_delay_specs(duration_s: float = 30.0) -> list[PositionSetSpec]:
    """Eight sets with a pure 30-40 ms channel delay of either sign (one and two joints,
    four representations, theta_ref in half): the long end of the realistic range,
    where the first search named another effect."""
    reps = ("float64", "sig7", "dec6", "float32_csv")
    return [PositionSetSpec(f"pos{n}-channel_delay-long{i}", (("channel_delay",
                                                             {"delay_s": d}),),
                            n_dof=n, seed=500 + i, duration_s=duration_s,
                            representation=reps[i % 4], record_ref=bool(i % 2))
            for i, (d, n) in enumerate(LONG_DELAYS)]


def draw_outside(rng: np.random.Generator, name: str) -> dict:
    """Magnitudes of the outside effects of position experiments (each large enough to
    leave a significant nominal gap)."""
    lu = lambda lo, hi: float(math.exp(rng.uniform(math.log(lo), math.log(hi))))  # noqa
    if name == "cubic_stiffness":
        return {"k3": lu(5e4, 2e5)}
    if name == "quadratic_damping":
        return {"b2": lu(1.0, 4.0)}
    if name == "tremor":
        return {"rms_nm": lu(0.1, 0.3), "frequency_hz": float(rng.uniform(8, 12)),
                "seed": int(rng.integers(1, 10_000))}
    if name == "backlash":
        return {"width_rad": lu(1e-3, 3e-3)}
    raise ValueError(f"unknown outside effect {name!r}")


class _ReportView:
    """What diagnosis.validation.score_one reads, from a PositionDiagnosis."""

    def __init__(self, d):
        if not isinstance(d, lf.PositionDiagnosis):  # a pipeline report: as it is
            self.__dict__.update({k: getattr(d, k) for k in (
                "verdict", "named", "fitted", "ranking", "gap", "elapsed_s", "amplitude",
                "conventions", "n_simulations")})
            return
        self.verdict, self.named, self.fitted = d.verdict, d.named, d.fitted
        self.ranking, self.gap, self.elapsed_s = d.ranking, d.gap, d.elapsed_s
        self.amplitude, self.conventions = {}, []
        self.n_simulations = d.n_evaluations


def diagnose_folder(folder, cfg: lf.FitConfig = lf.FitConfig(), *, via: str = "limbfit",
                    out_dir=None):
    """Diagnose the position trials of ``folder`` blind (never a truth file).

    ``via="limbfit"``: read them with trialformat and run :func:`limbfit.diagnose_position`
    (which / how far / verdict only, ``cfg``); ``via="pipeline"``: the whole diagnosis
    (:func:`diagnosis.diagnose`: read, conventions, estimate, nominal, where, which, how
    far, verdict, report into ``out_dir``), whose PositionServo experiment calls the same
    fits with its own settings.
    """
    if via == "pipeline":
        from .core import diagnose
        return diagnose(folder, out_dir, progress=False, workers=1)
    if via != "limbfit":
        raise ValueError(f"via must be 'limbfit' or 'pipeline', not {via!r}")
    import trialformat as tf
    trials = tf.read_trials(folder)
    return lf.diagnose_position(trials, cfg)


def score_position(d: lf.PositionDiagnosis, truth: dict) -> dict:
    """validation.score_one's row, plus the rectified choice and the intervals' cover."""
    from .validation import score_one
    row = score_one(_ReportView(d), truth)
    row["experiment"] = f"position-{truth['n_dof']}dof"
    row["theta_ref_recorded"] = truth["theta_ref_recorded"]
    row["intervals"] = intervals = getattr(d, "intervals", None) or {}
    for e in truth["effects"]:
        if "rectified" in e["params"] and e["name"] in d.fitted:
            row["rectified_correct"] = d.fitted[e["name"]].get("rectified") == \
                e["params"]["rectified"]
        ci = intervals.get(e["name"]) or {}
        row["truth_in_interval"] = {k: bool(lo <= e["params"][k] <= hi)
                                    for k, (lo, hi) in ci.items() if k in e["params"]}
    return row


def run_position_validation(specs, out_dir, *, cfg: lf.FitConfig = lf.FitConfig(),
                            progress: bool = True, workers: int = 1,
                            via: str = "limbfit", score_only: bool = False) -> dict:
    """Make, diagnose blind and score every set; resumable (a set's
    ``reports/NAME/score_row.json`` is written atomically once scored); ``workers``
    processes run sets side by side; ``via``: as :func:`diagnose_folder`; ``score_only``: score the sets already
    diagnosed (a run in progress or stopped) without running new ones. Writes
    ``score.json`` and ``score.md``."""
    from .validation import _jsonable, score_markdown, summarise
    out = Path(out_dir)
    todo = [s for s in specs if not (out / "reports" / s.name / "score_row.json").is_file()]
    if score_only:
        specs = [s for s in specs if s not in todo]
        todo = []
    if workers > 1 and len(todo) > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(workers) as pool:
            for i, _ in enumerate(pool.map(_run_one, todo, [out] * len(todo),
                                           [cfg] * len(todo), [via] * len(todo))):
                if progress:
                    print(f"[{i + 1}/{len(todo)}] {todo[i].name}", flush=True)
    else:
        for i, s in enumerate(todo):
            _run_one(s, out, cfg, via)
            if progress:
                print(f"[{i + 1}/{len(todo)}] {s.name}", flush=True)
    rows = [json.loads((out / "reports" / s.name / "score_row.json").read_text())
            for s in specs]
    summary = summarise(rows)
    summary["rectified_correct"] = _rate_of(rows, "rectified_correct")
    cover = [v for r in rows for v in (r.get("truth_in_interval") or {}).values()]
    from .validation import rate
    summary["truth_in_95pct_interval"] = rate(sum(cover), len(cover))
    md = score_markdown(summary, rows)
    _atomic_json(out / "score.json", _jsonable({"summary": summary, "rows": rows}))
    (out / "score.md").write_text(md, encoding="utf-8")
    return {"summary": summary, "rows": rows, "table_markdown": md}


def _rate_of(rows, key):
    from .validation import rate
    vals = [bool(r[key]) for r in rows if key in r]
    return rate(sum(vals), len(vals))


def _run_one(spec: PositionSetSpec, out: Path, cfg: lf.FitConfig, via: str = "limbfit"
             ) -> None:
    row_path = out / "reports" / spec.name / "score_row.json"
    row_path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    try:
        folder = make_position_set(spec, out / "sets")
        d = diagnose_folder(folder, cfg, via=via, out_dir=row_path.parent / "report")
        truth = json.loads(next(folder.glob("*" + TRUTH_SUFFIX)).read_text())  # scoring only
        row = {"set": spec.name, **score_position(d, truth),
               "truth_params": {n: p for n, p in spec.effects}, "ranking": d.ranking[:3],
               "gap": d.gap, "wall_s": time.perf_counter() - t0, "via": via}
    except Exception as exc:  # a set that cannot be made or diagnosed is reported
        row = {"set": spec.name, "error": f"{type(exc).__name__}: {exc}",
               "truth": sorted(n for n, _ in spec.effects)}
    _atomic_json(row_path, row)
