"""What modelica 0.0.205's flattener does with the constructs the correction fixes.

Run under the exporter's interpreter; prints JSON: for each probe, the flattener's own
result (``raw``) and the corrected one (``corrected``), as text.  Read by
``tests/plant/test_modelica_export.py``: the test fails when ``raw`` stops showing the
defect (upstream changed: the correction may be dropped or must be revised).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from correction import correct  # noqa: E402
from modelica.lang import parse  # noqa: E402
from modelica.sim import flatten  # noqa: E402

SOURCE = """
model Sub
  parameter Real k = 2;
  parameter Real q0[2] = {0.1, 0.2};
  input Real x[2];
  output Real y[2];
protected
  Real q[2] = q0 + x;
equation
  y = {k*q[1], k*q[2]};
end Sub;
model Probe
  parameter Real a[2] = {1.5, 2.5};
  parameter Real M[2, 2] = [1, 2; 3, 4];
  parameter Real d[2] = a*2;
  Sub sub(q0 = {0.3, 0.4});
  Real v[2](each start = 0, each fixed = true);
equation
  sub.x = v;
  der(v) = sub.y;
end Probe;
"""

PROBES = ("a[2]", "M[2, 1]", "d[2]", "sub.q0[2]")


def _text(node) -> str:
    return repr(node)


def main() -> int:
    program = parse(SOURCE, "probe.mo")
    raw = flatten(program, "Probe")
    fixed = correct(raw)
    out = {}
    for label, flat in (("raw", raw), ("corrected", fixed)):
        by = {v.name: v for v in flat.variables}
        out[label] = {name: _text(by[name].binding) for name in PROBES}
        out[label]["equations"] = [_text(e) for e in flat.equations
                                   if "sub" in _text(e) and ("'y[" in _text(e) or "'q[" in _text(e))]
    json.dump(out, sys.stdout, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
