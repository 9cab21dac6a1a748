"""The tractability study of docs/spec/reference-3dof.md: decomposition against MIMO as n grows.

For each number of joints n and total experiment time T:

* the decomposition: n trials of T/n, joint k perturbed alone (IMBIC masking), estimated
  by the paper's T/R (n SIMO identifications, nothing inverted) and by the bias-removing
  T P^-1 (the same n SIMO identifications, then the n x n response P inverted per
  frequency), both sampling and leakage corrected where the variant says so;
* the MIMO methods the paper cites, on one trial of T with every joint perturbed by
  independent signals: the closed-loop estimate (2n^2 FRFs from n perturbations, the
  n x n perturbation spectral matrix and the n x n response inverted per frequency) and
  the direct open-loop estimate (angles to torques, the n x n angle spectral matrix
  inverted).

Plants: n = 2 and 3 the C FMU (reference.md, reference-3dof.md); n = 4..7 the linear
pythonfmu plant (``orchestrator.plants.linear_arm``) with the chain of :func:`chain_arm`;
n = 3 also on the linear plant, to join the two. Condition: friction level 0 (the linear
plant has none), resolution level 2, perturbation level 3, reference tuning.

Measured per (n, T, estimator): VAF of every element (worst), M, B, K errors of every
element (worst; off-diagonal relative to sqrt(X_ii X_kk)), band-mean coherence (worst
element), the number of FRFs computed together, the largest condition number of what is
inverted per frequency over 0-15 Hz, and the computing time of estimation and fit.

``run_tractability(out)`` (CLI ``armimp tractability --out DIR``) simulates the trials
into ``out/trials`` (resumable, 2 processes), then writes ``out/tractability.json``,
``out/table.md`` and ``out/fig_tractability.png``.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
import warnings
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np
from tqdm import tqdm

from trialformat import reference as ref

from .errors import SetupError

FORMAT = "arm-impedance-tractability/1"
NS = (2, 3, 4, 5, 6, 7)
TOTALS_S = (70.0, 175.0, 350.0)
QUICK = {"ns": (2, 3, 4), "totals_s": (70.0,)}
CONDITION = {"friction_level": 0, "resolution_level": 2, "perturbation_level": 3}
#: (label, estimation variant): the paper's T/R, the bias-removing T P^-1, the MIMO pair.
ESTIMATORS = (("decomposition T/R", "decomposition"),
              ("decomposition T P^-1", "full_corrected"),
              ("MIMO closed loop", "closed_loop_corrected"),
              ("MIMO direct", "direct_sampling"))

# ---------------------------------------------------------------- the n-joint chain (choice)
#: Joints beyond the wrist (j >= 4): compact modules at the hand (a short planar link
#: each: small lever arms keep the chain's inertial coupling, and so the time-delay
#: estimation's ||I - M^-1 Mbar||, moderate), a relaxed distal joint, couplings to the two
#: proximal neighbours, the wrist's controller.
_DISTAL_LINK = {"m": 0.2, "L": 0.0, "lc": 0.0, "I": 0.0005, "Jm": 0.003, "q0_deg": 10.0}
_DISTAL_ARM = {"diag": (0.004, 0.04, 2.0), "near": (0.0005, 0.010, 0.3), "decay": 0.4}
#: Mbar of joints 1-3 in the chain (n >= 4): twice reference-3dof.md's. With the reference
#: Mbar the held joint 1 diverges within 2 s in the decomposition trials of joints >= 3
#: at n = 4 and 7 (the chain's larger M_11; measured); 2x is stable at n = 4..7.
_CHAIN_MBAR_SCALE = 2.0
_DISTAL_CONTROLLER = {"M_rd": 0.02, "B_rd": 0.2, "K_rd": 2.0, "theta_rd_deg": 0.0,
                      "Mbar": 0.003, "wn": 150.0}
_DISTAL_PEAK = 1.2  # [N m] at perturbation level 3 (the wrist: 1.8)


def chain_arm(n: int):
    """Arm matrices (M_h, B_h, K_h) (n, n) of the n-joint chain: reference-3dof.md's for
    joints 1-3 (Table I for n = 2), then distal joints with :data:`_DISTAL_ARM`: symmetric
    couplings to every proximal joint, ``near`` to the previous one, times ``decay`` per
    joint further away."""
    if n < 2:
        raise SetupError(f"the chain has n >= 2 joints, got {n!r}")
    base = ref.arm_matrices("2dof" if n == 2 else "3dof")
    if n <= 3:
        return base
    out = []
    for which, mat in enumerate(base):
        X = np.zeros((n, n))
        X[:3, :3] = mat
        for j in range(3, n):  # couplings decay with distance (no element exactly 0)
            X[j, j] = _DISTAL_ARM["diag"][which]
            for i in range(j):
                X[j, i] = X[i, j] = _DISTAL_ARM["near"][which] * _DISTAL_ARM["decay"] ** (j - 1 - i)
        out.append(X)
    return tuple(out)


def planar_mass_matrix(links, Jm, q_deg) -> np.ndarray:
    """M_r(q) [kg m^2] (n, n) of a planar serial chain (the C plant's formula,
    fmus/ArmExoPlant/model_nlink.c) plus diag(Jm).

    links : sequence of (m, L, lc, I); Jm : (n,); q_deg : (n,) posture (relative angles).
    """
    n = len(links)
    m, L, lc, inertia = (np.array([lk[i] for lk in links], float) for i in range(4))
    tail = np.array([m[a + 1:].sum() for a in range(n)])
    d = np.empty((n, n))
    for a in range(n):
        d[a, a] = inertia[a] + m[a] * lc[a] ** 2 + L[a] ** 2 * tail[a]
        for b in range(a + 1, n):
            d[a, b] = d[b, a] = L[a] * (m[b] * lc[b] + L[b] * tail[b])
    phi = np.cumsum(np.radians(q_deg))
    D = d * np.cos(phi[:, None] - phi[None, :])
    S = np.tril(np.ones((n, n)))
    return S.T @ D @ S + np.diag(Jm)


def chain_robot(n: int):
    """(M_r at the posture, posture_deg) of the n-joint linear plant: reference-3dof.md's
    three links and motors, then :data:`_DISTAL_LINK` links."""
    r3 = ref.reference("3dof")
    rob = r3["robot"]
    links = [(rob[f"m{i}"], rob[f"L{i}"], rob[f"lc{i}"], rob[f"I{i}"]) for i in (1, 2, 3)]
    Jm = list(rob["Jm"])
    posture = list(r3["human_arm"]["posture_deg"])
    if n == 2:
        r2 = ref.reference("2dof")["robot"]
        links, Jm, posture = links[:2], list(r2["Jm"]), posture[:2]
        links = [(r2[f"m{i}"], r2[f"L{i}"], r2[f"lc{i}"], r2[f"I{i}"]) for i in (1, 2)]
    dl = _DISTAL_LINK
    for _ in range(3, n):
        links.append((dl["m"], dl["L"], dl["lc"], dl["I"]))
        Jm.append(dl["Jm"])
        posture.append(dl["q0_deg"])
    return planar_mass_matrix(links, Jm, posture), posture


def chain_setup(n: int, resolution_level: int = CONDITION["resolution_level"]):
    """The Setup of the n-joint study: the reference Setup for n = 2, 3 (friction level 0),
    else the chain on the linear plant (no robot block; controller: reference-3dof.md's
    with joints 1-3's Mbar scaled by :data:`_CHAIN_MBAR_SCALE`, distal joints
    :data:`_DISTAL_CONTROLLER`)."""
    from .setup import Setup

    if n in (2, 3):
        return Setup.reference(CONDITION["friction_level"], resolution_level,
                               arm=f"{n}dof")
    c3 = ref.controller("reference", "3dof")
    block = {k: list(c3[k]) + [_DISTAL_CONTROLLER[k]] * (n - 3)
             for k in ("M_rd", "B_rd", "K_rd", "theta_rd_deg", "Mbar", "wn")}
    block["Mbar"][:3] = [_CHAIN_MBAR_SCALE * v for v in block["Mbar"][:3]]
    block["tuning"] = "custom"
    _, posture = chain_robot(n)
    return Setup(n_dof=n, fs=1.0 / ref.reference()["timing"]["control_period_s"],
                 posture_deg=posture, robot={}, friction=ref.friction_level(0, n),
                 sensors=ref.sensor_level(resolution_level), controller=block,
                 arm=chain_arm(n), levels={"friction_level": 0,
                                           "resolution_level": resolution_level})


def chain_peaks(n: int, level: int = CONDITION["perturbation_level"]) -> list:
    """Perturbation peaks per joint [N m]: the reference's for joints 1-3, then
    :data:`_DISTAL_PEAK` scaled by level / 3."""
    base = ref.perturbation_peak(level, "2dof" if n == 2 else "3dof")
    return list(base[:n]) + [_DISTAL_PEAK * level / 3.0] * max(0, n - 3)


# ---------------------------------------------------------------- tasks
def plant_kinds(ns) -> list:
    """(n, plant) pairs: "fmu" for n = 2, 3; "linear" for n >= 4 and for n = 3."""
    out = []
    for n in ns:
        if n in (2, 3):
            out.append((n, "fmu"))
        if n >= 3:
            out.append((n, "linear"))
    return out


def study_tasks(ns=NS, totals_s=TOTALS_S) -> list:
    """One task per trial: per (n, plant, T) n decomposition trials of T/n and one
    all-joints trial of T. Seeds depend on n and the joint only (T cuts the same signal)."""
    tasks = []
    for n, plant in plant_kinds(ns):
        for total in totals_s:
            for k in list(range(1, n + 1)) + [None]:
                dur = total / n if k is not None else total
                tasks.append({"n": n, "plant": plant, "total_s": float(total),
                              "perturbed_dof": k, "duration_s": dur,
                              "seed": 1000 + 10 * n + (0 if k is None else k),
                              "name": trial_stem(n, plant, total, k)})
    return tasks


def trial_stem(n, plant, total, dof) -> str:
    return f"n{n}_{plant}_T{int(round(total))}_dof{'all' if dof is None else dof}"


def linear_plant_path(out: Path, n: int) -> Path:
    return Path(out) / "plants" / f"linear_arm_n{n}.fmu"


def build_linear_plants(out: Path, ns) -> dict:
    """pythonfmu linear plants of the chain for every n >= 3 in ns (built once)."""
    from .plants import build_linear_arm_fmu

    paths = {}
    for n in ns:
        if n < 3:
            continue
        path = linear_plant_path(out, n)
        if not path.is_file():
            M_r, posture = chain_robot(n)
            build_linear_arm_fmu(path.parent, module_name=path.stem, arm=chain_arm(n),
                                 M_r=M_r, posture_deg=posture)
        paths[n] = str(path)
    return paths


def run_task(task: dict, trials_dir: str, plant_paths: dict) -> dict:
    """Simulate and write one trial; never raises (the failure is returned)."""
    from trialformat import write_trial

    from .perturbation import make_perturbation
    from .trial import simulate_trial

    start = time.perf_counter()
    res = dict(task)
    try:
        n = task["n"]
        setup = chain_setup(n)
        plant = None if task["plant"] == "fmu" else plant_paths[str(n)]
        samples = int(round(task["duration_s"] * setup.fs))
        tau = make_perturbation(CONDITION["perturbation_level"], task["seed"], samples, n,
                                setup.fs, task["perturbed_dof"], peak=chain_peaks(n))
        trial = simulate_trial(setup, perturbed_dof=task["perturbed_dof"], perturbation=tau,
                               plant=plant, name=task["name"])
        write_trial(Path(trials_dir) / task["name"], trial)
        res["status"] = "done"
    except Exception as exc:  # one failure must not stop the study
        res.update(status="failed", error=f"{type(exc).__name__}: {exc}")
    res["wall_s"] = round(time.perf_counter() - start, 3)
    return res


# ---------------------------------------------------------------- estimation measures
def frfs_together(method: str, n: int) -> str:
    """The number of FRFs computed together by a method (one input -> outputs at once)."""
    return {"decomposition": f"{n} x {2 * n} (n SIMO)", "full": f"{n} x {2 * n} (n SIMO)",
            "closed_loop": f"{2 * n * n} (MIMO)", "direct": f"{n * n} (MIMO)"}[method]


def conditioning(trials, method: str, est) -> float:
    """Largest condition number over 0 < f <= 15 Hz of what the method inverts per
    frequency: nothing for T/R (1); the response P for T P^-1; the perturbation spectral
    matrix and P for the closed loop (the larger); the angle spectral matrix for direct."""
    from estimation import spectral

    band = est.band & (est.f > 0)
    if method == "decomposition":
        return 1.0
    if method == "full":
        return float(np.linalg.cond(est.P[band]).max())
    use = [t for t in trials if t.perturbed_dof is None]
    x = np.vstack([t.tau_delta if method == "closed_loop" else t.theta for t in use])
    f, G = spectral.cross_spectrum(x, x, fs=est.fs, nperseg=spectral.NPERSEG,
                                   noverlap=spectral.NOVERLAP, nfft=spectral.NFFT,
                                   window=spectral.WINDOW, detrend=spectral.DETREND)
    cond = float(np.linalg.cond(G[band]).max())
    if method == "closed_loop":
        cond = max(cond, float(np.linalg.cond(est.P[band]).max()))
    return cond


def matrix_vaf(est, truth, compensate, leakage) -> float:
    """VAF [%] of the whole n x n impedance over the band: 100 (1 - sum |Zhat - Z|^2 /
    sum |Z|^2) over every element and bin (small couplings weigh by their size)."""
    from estimation.accuracy import true_impedance
    from estimation.conditions import _fit_and_impedance

    _, Z = _fit_and_impedance(est, compensate, leakage)
    Zt = true_impedance(est.f[est.band], *truth)
    return float(100.0 * (1.0 - np.sum(np.abs(Z - Zt) ** 2) / np.sum(np.abs(Zt) ** 2)))


def evaluate_case(trials, truth) -> list:
    """One row per estimator of :data:`ESTIMATORS` for the trials of one (n, plant, T)."""
    from estimation.conditions import _fit_and_impedance, score, variant_spec
    from estimation.estimator import estimate_impedance

    from .paper import normalized_errors

    rows = []
    for label, variant in ESTIMATORS:
        _, method, compensate, leakage = variant_spec(variant)
        single = method in ("decomposition", "full")
        use = [t for t in trials if (t.perturbed_dof is not None) == single]
        n = trials[0].n_dof
        row = {"estimator": label, "variant": variant, "method": method,
               "frfs_together": frfs_together(method, n),
               "trial_s": round(use[0].n_samples / use[0].fs, 3) if use else None}
        try:
            t0 = time.perf_counter()
            est = estimate_impedance(use, method=method)
            _fit_and_impedance(est, compensate, leakage)
            row["compute_s"] = time.perf_counter() - t0
            scored = score(est, truth=truth, compensate=compensate, leakage=leakage,
                           name=variant)
        except Exception as exc:  # e.g. a trial shorter than one Welch segment
            row.update(status="failed", error=f"{type(exc).__name__}: {exc}")
            rows.append(row)
            continue
        err = normalized_errors(scored, truth)
        row.update(status="done", vaf_min=scored["vaf_min"],
                   vaf_matrix=matrix_vaf(est, truth, compensate, leakage),
                   coh_min=scored["coh_min"],
                   err_M=err["M"], err_B=err["B"], err_K=err["K"],
                   n_segments=int(est.n_segments),
                   cond_max=conditioning(use, method, est))
        rows.append(row)
    return rows


# ---------------------------------------------------------------- the study
def run_tractability(out, *, ns=NS, totals_s=TOTALS_S, quick=False, workers=2,
                     progress=True) -> dict:
    """Run the study into ``out`` (resumable); return the result (also
    ``out/tractability.json``).

    Parameters
    ----------
    out : path
    ns : sequence of int
        Numbers of joints (2..7).
    totals_s : sequence of float [s]
        Total experiment times T (each >= n x 8.192 s for a Welch segment per trial).
    quick : bool
        :data:`QUICK` (n = 2, 3, 4, T = 70 s) instead of ``ns``/``totals_s``.
    workers : int
        Local processes for the trials.
    """
    from trialformat import read_trial, trial_exists

    if quick:
        ns, totals_s = QUICK["ns"], QUICK["totals_s"]
    bad = [n for n in ns if not 2 <= int(n) <= 7]
    if bad:
        raise SetupError(f"the study has n in 2..7, got {bad}")
    bad = [T for T in totals_s if not (isinstance(T, (int, float)) and np.isfinite(T)
                                       and T > 0)]
    if bad:  # before any folder or plant is made
        raise SetupError(f"total experiment times must be finite and > 0 [s], got {bad} "
                         f"(e.g. --totals 70 175 350)")
    out = Path(out)
    trials_dir = out / "trials"
    trials_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    plants = {str(k): v for k, v in build_linear_plants(out, ns).items()}
    tasks = study_tasks(ns, totals_s)
    todo = [t for t in tasks if not trial_exists(trials_dir / t["name"])]
    failures = []
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="trials",
               unit="trial", disable=None if progress else True)
    try:
        for res in _execute(todo, str(trials_dir), plants, workers):
            bar.update(1)
            if res["status"] == "failed":
                failures.append(res)
                bar.write(f"FAILED {res['name']}: {res['error']}")
    finally:
        bar.close()
    sim_s = time.perf_counter() - start
    cases = []
    keys = sorted({(t["n"], t["plant"], t["total_s"]) for t in tasks})
    for n, plant, total in tqdm(keys, desc="estimating", disable=None if progress else True):
        group = [t for t in tasks if (t["n"], t["plant"], t["total_s"]) == (n, plant, total)]
        try:
            with warnings.catch_warnings():  # the chain declares no robot block: the reader
                warnings.simplefilter("ignore", UserWarning)  # fills it, unused here
                trials = [read_trial(trials_dir / f"{t['name']}.csv", min_samples=1)
                          for t in group]
        except Exception as exc:
            cases.append({"n": n, "plant": plant, "total_s": total, "status": "failed",
                          "error": f"{type(exc).__name__}: {exc}"})
            continue
        for row in evaluate_case(trials, chain_arm(n)):
            cases.append({"n": n, "plant": plant, "total_s": total, **row})
    result = {"format": FORMAT, "condition": CONDITION, "ns": list(ns),
              "totals_s": list(totals_s), "failures": failures, "rows": cases,
              "wall_s": {"trials": round(sim_s, 1),
                         "total": round(time.perf_counter() - start, 1)}}
    _atomic(out / "tractability.json", json.dumps(result, indent=1))
    _atomic(out / "table.md", table_markdown(cases))
    figure(cases, out / "fig_tractability.png")
    return result


def _execute(tasks, trials_dir, plants, workers):
    if not tasks:
        return
    if workers <= 1:
        for t in tasks:
            yield run_task(t, trials_dir, plants)
        return
    # longest first: the pool stays busy to the end
    tasks = sorted(tasks, key=lambda t: -t["duration_s"])
    from trialformat.processes import process_pool

    with process_pool(workers) as ex:  # Ctrl-C stops the workers at once
        futures = [ex.submit(run_task, t, trials_dir, plants) for t in tasks]
        for fut in as_completed(futures):
            yield fut.result()


def table_markdown(rows) -> str:
    cols = ("n", "plant", "total_s", "estimator", "trial_s", "n_segments", "frfs_together",
            "cond_max",
            "vaf_matrix", "vaf_min", "err_M", "err_B", "err_K", "coh_min", "compute_s")
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        if r.get("status") != "done":
            lines.append(f"| {r['n']} | {r['plant']} | {r['total_s']:g} | "
                         f"{r.get('estimator', '')} | {r.get('trial_s', '')} | "
                         f"{r.get('frfs_together', '')} | failed: {r.get('error', '')} |")
            continue
        vals = []
        for c in cols:
            v = r.get(c)
            if c == "cond_max":
                vals.append(f"{v:.3g}")
            elif c == "compute_s":
                vals.append(f"{v:.2f}")
            elif c in ("vaf_min", "vaf_matrix", "err_M", "err_B", "err_K"):
                vals.append(f"{v:.2f}")
            elif c == "coh_min":
                vals.append(f"{v:.4f}")
            elif isinstance(v, float):
                vals.append(f"{v:g}")
            else:
                vals.append(str(v))
        lines.append("| " + " | ".join(vals) + " |")
    legend = ("\nPer n, plant and total experiment time T: the decomposition runs n trials "
              "of T/n (trial_s), the MIMO methods one trial of T; n_segments: Welch segments of 8192 "
              "samples per trial (one segment: no averaging, coherence 1 by construction). vaf_matrix [%]: VAF of the whole "
              "matrix (every element and bin); vaf_min [%]: worst element; "
              "err_M/B/K [%]: largest error of every element, off-diagonal relative to "
              "sqrt(X_ii X_kk); coh_min: worst band-mean coherence; cond_max: largest "
              "condition number over 0-15 Hz of the matrices inverted per frequency (1: "
              "nothing inverted); compute_s: estimation and fit [s].\n")
    return "\n".join(lines) + "\n" + legend


def figure(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [r for r in rows if r.get("status") == "done"]
    totals = sorted({r["total_s"] for r in done})
    panels = (("vaf_matrix", "VAF of Z [%]", False), ("err_M", "worst M error [%]", True),
              ("err_B", "worst B error [%]", True), ("err_K", "worst K error [%]", True),
              ("cond_max", "max cond. number", True), ("compute_s", "computing time [s]", True))
    fig, axes = plt.subplots(len(totals) or 1, len(panels),
                             figsize=(18, 2.8 * max(len(totals), 1) + 0.6), squeeze=False)
    styles = {"decomposition T/R": "o-", "decomposition T P^-1": "s-",
              "MIMO closed loop": "^--", "MIMO direct": "v--"}
    for a, total in enumerate(totals):
        for label, _ in ESTIMATORS:
            sel = sorted((r for r in done if r["total_s"] == total and r["estimator"] == label
                          and not (r["n"] == 3 and r["plant"] == "linear")),
                         key=lambda r: r["n"])
            for ax, (key, ylabel, log) in zip(axes[a], panels):
                y = [r[key] for r in sel]
                if key == "vaf_matrix":  # a failed estimate (VAF << 0) at the axis floor
                    y = [max(v, 90.0) for v in y]
                ax.plot([r["n"] for r in sel], y, styles[label], label=label, ms=4)
                if log:
                    ax.set_yscale("log")
                ax.set_ylabel(ylabel)
                ax.set_title(f"T = {total:g} s", fontsize=9)
                ax.set_xlabel("number of joints n")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Tractability: decomposition (n trials of T/n) vs MIMO (one trial of T) "
                 "at equal total experiment time T; n = 2, 3 C FMU, n >= 4 linear plant")
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.png")
    fig.savefig(tmp, dpi=65)
    plt.close(fig)
    os.replace(tmp, path)


def _atomic(path: Path, text: str) -> None:
    from trialformat.logs import current_umask

    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp's 0600 -> the user's umask
    os.replace(tmp, path)


def summary_lines(result) -> list:
    """A short text summary: one line per (n, plant, T, estimator)."""
    lines = []
    for r in result["rows"]:
        if r.get("status") == "done":
            lines.append(f"n={r['n']} {r['plant']:6s} T={r['total_s']:5g} s "
                         f"{r['estimator']:21s} VAF(Z) {r['vaf_matrix']:7.2f} %  "
                         f"VAF min {r['vaf_min']:7.2f} %  "
                         f"M {r['err_M']:6.2f} %  B {r['err_B']:6.2f} %  K {r['err_K']:6.2f} %  "
                         f"coh {r['coh_min']:.3f}  cond {r['cond_max']:9.3g}  "
                         f"{r['compute_s']:.2f} s")
        else:
            lines.append(f"n={r['n']} {r['plant']} T={r['total_s']:g} s "
                         f"{r.get('estimator', '')}: {r.get('error')}")
    lines += [f"FAILED trial {f['name']}: {f['error']}" for f in result["failures"]]
    return lines
