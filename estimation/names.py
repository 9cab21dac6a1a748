"""Names the command line needs before any numerical module is loaded (no numpy here).

The estimator methods (estimation.estimator), the recommended and the paper's variant
(estimation.conditions), and the fit weightings (estimation.accuracy) are defined here
once and imported by those modules, so that ``python -m orchestrator --help`` builds its
parser without numpy, scipy or matplotlib (bench/bench_startup.py).
"""

METHODS = ("decomposition", "full", "closed_loop", "direct")

#: The recommended (bias-removing) variant and the paper's plain T/R.
RECOMMENDED = "full_corrected"
PAPER = "decomposition"

#: Weightings of the second-order fit (estimation.accuracy): from the data, solved once
#: (``coherence``, ``smoothed``, ``relative``, ``none``), or ``model``: ``1/|Zfit|`` of a
#: first ``relative`` fit (two passes; the paper grid's fit, docs/estimation.md).
WEIGHTINGS = ("coherence", "smoothed", "relative", "none", "model")
