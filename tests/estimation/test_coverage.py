"""Monte Carlo coverage of the 95 % intervals of M, B, K (slow: 200 seeds, ~1-2 min).

The full table is bench/bench_coverage.py; this checks the position-perturbation case
with a recorded reference and the exact torque-perturbation case against 90-98 %.
"""

import numpy as np
import pytest

from estimation.lab import Unit, analyse
from estimation.synthetic import position_trial, torque_trial

ANKLE = {"K": 150.0, "B": 1.5, "I": 0.015}


@pytest.mark.slow
@pytest.mark.parametrize("make", [position_trial, torque_trial])
def test_95_percent_intervals_cover_90_to_98_percent_of_200_seeds(make):
    hits = []
    for seed in range(200):
        r = analyse(Unit("mc", [make(**ANKLE, seed=seed)], ""))
        hits.append([abs(getattr(r.fit, p)[0, 0] - true) <= getattr(r.fit, f"{p}_ci")[0, 0]
                     for p, true in (("M", ANKLE["I"]), ("B", ANKLE["B"]), ("K", ANKLE["K"]))])
    coverage = np.mean(hits, axis=0)
    assert np.all((coverage >= 0.90) & (coverage <= 0.98)), coverage
