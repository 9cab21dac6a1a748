"""Stage 5, where: the nominal gap broken down by signal, joint, band, kind and
perturbation level, its coherent share, the sample grids, and whether the residual
depends on the perturbation amplitude."""

from __future__ import annotations

import numpy as np

from ..config import AMPLITUDE_GAP
from ..conventions import merged_texts
from ..evaluation import storage_context
from ..gap import GapResult


def run(r) -> None:
    """Fill ``r.where`` (keys documented in docs/diagnosis.md)."""
    r.where = {"conventions": merged_texts(r.findings),  # a repeat said once, counted
               "storage": {t.name: storage_context(t).describe() for t in r.trials},
               "grid": grids(r.trials, r.experiment),
               "nominal": where_breakdown(r.nominal_all),
               "named": None}


def where_breakdown(result: GapResult) -> dict:
    """The gap broken down for the report (keys documented in docs/diagnosis.md)."""
    def rows(*keys):
        return [{**dict(zip(keys, k)), "gap": v}
                for k, v in sorted(result.breakdown(*keys).items(), key=lambda kv: -kv[1])]
    bands = rows("kind", "signal", "joint", "band")
    return {"total": result.value, "coherent_share": result.coherent_share(),
            "by_signal": rows("signal"), "by_joint": rows("joint"), "by_kind": rows("kind"),
            "by_level": rows("level"), "by_signal_kind": rows("signal", "kind"),
            "by_band": bands, "top_bands": bands[:5]}


def amplitude_dependence(result: GapResult, trials) -> dict:
    """Does the residual change with the perturbation amplitude?

    For every two trials of the same perturbed joint at different perturbation levels,
    the coherent (FRF) features of the residual are compared: a model error that is linear
    leaves the same difference d = measured - model at every amplitude (FRFs do not
    depend on it), so ``mean(((d_a - d_b)^2 - 2 v_a - 2 v_b) / (sigma_a^2 + sigma_b^2))``
    is ~0 (v the statistical variances); a nonlinearity the model lacks makes it large. Returns ``{"statistic", "threshold", "amplitude_dependent",
    "pairs": [{trials, levels, statistic}]}`` (statistic None without two levels).
    """
    info = {t.name: (t.perturbed_dof, (t.meta.get("perturbation") or {}).get("level"))
            for t in trials}
    by_trial: dict = {}
    for pos, lab in enumerate(result.labels):
        if lab[2] == "frf":
            by_trial.setdefault(lab[0], []).append(pos)
    pairs = []
    names = sorted(by_trial)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            (ka, la), (kb, lb) = info[a], info[b]
            if ka != kb or la is None or lb is None or la == lb:
                continue
            pa, pb = by_trial[a], by_trial[b]
            if len(pa) != len(pb):
                continue
            sa, sb = result.sigma[pa], result.sigma[pb]
            use = np.isfinite(sa) & np.isfinite(sb)
            if not use.any():
                continue
            da, db = result.z[pa][use] * sa[use], result.z[pb][use] * sb[use]
            va = result.expected[pa][use] * sa[use] ** 2 / 2.0  # e = 2 v / sigma^2
            vb = result.expected[pb][use] * sb[use] ** 2 / 2.0
            diff = np.angle(np.exp(1j * (da - db)))  # phases: wrapped; ln|H|: small
            stat = float(np.mean((diff ** 2 - 2 * va - 2 * vb)
                                 / (sa[use] ** 2 + sb[use] ** 2)))
            pairs.append({"trials": [a, b], "levels": [la, lb], "statistic": stat})
    worst = max((p["statistic"] for p in pairs), default=None)
    return {"statistic": worst, "threshold": AMPLITUDE_GAP,
            "amplitude_dependent": bool(worst is not None and worst > AMPLITUDE_GAP),
            "pairs": pairs}


def rest_where(result: GapResult, n: int = 3) -> list:
    """The feature groups that carry most of a residual, as readable strings."""
    rows = where_breakdown(result)["top_bands"][:n]
    return [f"{r['signal']}[{r['joint']}] {r['kind']} {r['band']} (gap {r['gap']:.3g})"
            for r in rows if r["gap"] > 0]


def grids(trials, experiment=None) -> dict:
    """The quantisation grid found in theta and tau_h of every trial, with its
    uncertainty (step 0: none resolvable at the storage precision)."""
    out = {}
    for t in trials:
        context = storage_context(t)
        out[t.name] = {s: [context.grid(s, j, t.signal(s)[:, j]).to_dict()
                           for j in range(t.n_dof)] for s in ("theta", "tau_h")}
    return out
