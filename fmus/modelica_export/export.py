"""Export C from the Modelica package with modelica==0.0.205 (run by fmus.modelica_build).

Usage (the exporter's interpreter, Python >= 3.12)::

    python3.12 fmus/modelica_export/export.py PACKAGE_DIR MODEL OUT.json

Parses every file of the package (``package.mo`` + ``package.order``, nested by folder),
flattens ``MODEL`` (e.g. ``ArmExo.ArmExoPlant``), applies the flattener correction
(``correction.py``), causalises (BLT, tearing) and emits C with ``modelica.sim.cgen``.
Writes one JSON file: the generated C (``rhs``, ``observe``; the top-level inputs read
from ``p[NP + k]``, which the generated code leaves undeclared-uninitialised), the state
names and start values, every parameter with its slot in ``p``, unit, description, start
value and minimum, the dependent ("calculated") parameters as C expressions in evaluation
order, the inputs and the observed slots.  Fails with a message naming what it cannot do.
"""
from __future__ import annotations

import dataclasses
import json
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from correction import correct  # noqa: E402
from modelica.ir import nodes as ir  # noqa: E402
from modelica.lang import parse  # noqa: E402
from modelica.sim import causalize, cgen, flatten  # noqa: E402
from modelica.sim.dialect import C  # noqa: E402
from modelica.sim.emit import Emitter  # noqa: E402


class ExportError(RuntimeError):
    pass


def load(folder: Path) -> ir.Class:
    """The package in ``folder`` (package.mo, package.order, one class per file)."""
    pkg_file = folder / "package.mo"
    pkg = parse(pkg_file.read_text(), str(pkg_file)).classes[0]
    subs = []
    for name in (folder / "package.order").read_text().split():
        if (folder / name).is_dir():
            subs.append(load(folder / name))
        else:
            f = folder / f"{name}.mo"
            subs.extend(parse(f.read_text(), str(f)).classes)
    return dataclasses.replace(pkg, classes=pkg.classes + tuple(subs))


def c_expr(node, symbol) -> str:
    """A parameter binding as C (literals, names via ``symbol``, + - * / ^, if, min/max)."""
    e = lambda x: c_expr(x, symbol)  # noqa: E731
    match node:
        case ir.RealLiteral(value=v):
            return repr(float(v))
        case ir.IntLiteral(value=v):
            return f"{float(v)!r}"
        case ir.BoolLiteral(value=v):
            return "1.0" if v else "0.0"
        case ir.Ref():
            return symbol(node.name)
        case ir.Unary(op="-", operand=x):
            return f"(-{e(x)})"
        case ir.Unary(op="not", operand=x):
            return f"(!({e(x)}) ? 1.0 : 0.0)"
        case ir.Binary(op="^", lhs=a, rhs=b):
            return f"pow({e(a)}, {e(b)})"
        case ir.Binary(op=op, lhs=a, rhs=b) if op in ("+", "-", "*", "/"):
            return f"({e(a)} {op} {e(b)})"
        case ir.Binary(op=op, lhs=a, rhs=b) if op in (">", "<", ">=", "<=", "==", "<>"):
            cop = "!=" if op == "<>" else op
            return f"(({e(a)} {cop} {e(b)}) ? 1.0 : 0.0)"
        case ir.Binary(op="and", lhs=a, rhs=b):
            return f"(({e(a)} != 0.0 && {e(b)} != 0.0) ? 1.0 : 0.0)"
        case ir.Binary(op="or", lhs=a, rhs=b):
            return f"(({e(a)} != 0.0 || {e(b)} != 0.0) ? 1.0 : 0.0)"
        case ir.IfExpr(condition=c, then=a, otherwise=b):
            return f"(({e(c)}) != 0.0 ? {e(a)} : {e(b)})"
        case ir.Call(name=fn, args=args) if fn in ("min", "max") and len(args) >= 1:
            out = e(args[0])
            for a in args[1:]:
                out = f"md_{fn}({out}, {e(a)})"
            return out
        case ir.Call(name=fn, args=(x,)) if fn in ("sin", "cos", "tan", "exp", "sqrt", "abs"):
            return f"{'fabs' if fn == 'abs' else fn}({e(x)})"
    raise ExportError(f"cannot write the parameter binding {node!r} as C")


def literal(node):
    match node:
        case ir.RealLiteral(value=v) | ir.IntLiteral(value=v):
            return float(v)
        case ir.BoolLiteral(value=v):
            return 1.0 if v else 0.0
        case ir.Unary(op="-", operand=x):
            v = literal(x)
            return None if v is None else -v
    return None


def export(folder: Path, model: str) -> dict:
    t0 = time.perf_counter()
    flat = correct(flatten(ir.Program((load(folder),)), model))
    t1 = time.perf_counter()
    system = causalize(flat)
    t2 = time.perf_counter()
    source = cgen.unit(system)
    t3 = time.perf_counter()
    emitter = Emitter(system, dialect=C)
    params = list(system.parameters)
    index = {v.name: k for k, v in enumerate(params)}
    np_ = len(params)
    inputs = [v for v in flat.variables if v.causality == "input"]
    # the generated code declares each top-level input and never sets it: read it from p
    for k, v in enumerate(inputs):
        sym = emitter.symbols[v.name]
        pattern = re.compile(rf"^(\s*)double {re.escape(sym)};$", re.M)
        source, count = pattern.subn(rf"\1double {sym} = p[{np_ + k}];", source)
        if count == 0 and sym in source:
            raise ExportError(f"the generated C uses the input {v.name} ({sym}) without a "
                              "declaration to initialise: the exporter's output changed")
    for k, v in enumerate(inputs):
        if re.search(rf"\bdouble {re.escape(emitter.symbols[v.name])};", source):
            raise ExportError(f"input {v.name} left uninitialised")

    def symbol(name):
        if name not in index:
            raise ExportError(f"a parameter binding names {name!r}, which is no parameter")
        return f"p[{index[name]}]"

    parameters, dependent = [], []
    for k, v in enumerate(params):
        value = literal(v.binding) if v.binding is not None else (
            literal(v.start) if v.start is not None else 0.0)
        entry = {"name": v.name, "slot": k, "unit": v.unit, "description": v.comment,
                 "type": v.base_type, "min": literal(v.minimum) if v.minimum is not None else None,
                 "independent": v.binding is None or value is not None}
        if entry["independent"]:
            entry["start"] = 0.0 if value is None else value
        else:
            entry["c"] = c_expr(v.binding, symbol)
            dependent.append(k)
        parameters.append(entry)
    # dependent parameters in an order where each follows those it reads
    order, done = [], {k for k, p in enumerate(parameters) if p["independent"]}
    pending = list(dependent)
    while pending:
        progressed = False
        for k in list(pending):
            reads = {int(m) for m in re.findall(r"p\[(\d+)\]", parameters[k]["c"])}
            if reads <= done:
                order.append(k)
                done.add(k)
                pending.remove(k)
                progressed = True
        if not progressed:
            raise ExportError("cyclic parameter bindings: "
                              + ", ".join(parameters[k]["name"] for k in pending))
    by_name = {v.name: v for v in flat.variables}
    states = []
    for name in system.states:
        v = by_name[name]
        start = literal(v.start) if v.start is not None else 0.0
        if start is None:
            raise ExportError(f"the start value of state {name} is not a literal")
        states.append({"name": name, "start": start, "unit": v.unit, "description": v.comment})
    observed = {name: slot for name, slot in emitter.slots.items()}
    variables = {v.name: {"unit": v.unit, "description": v.comment, "causality": v.causality,
                          "variability": v.variability} for v in flat.variables}
    return {"model": model, "generator": "modelica 0.0.205 (modelica.sim.cgen) + fmus/modelica_export",
            "c": source, "n_parameters": np_, "parameters": parameters, "dependent_order": order,
            "inputs": [{"name": v.name, "unit": v.unit, "description": v.comment} for v in inputs],
            "states": states, "observed": observed, "n_observed": 1 + max(observed.values()),
            "variables": variables,
            "symbols": {v.name: emitter.symbols[v.name] for v in params if v.name in emitter.symbols},
            "seconds": {"flatten": t1 - t0, "causalize": t2 - t1, "emit": t3 - t2}}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3:
        print(__doc__.splitlines()[2], file=sys.stderr)
        return 2
    folder, model, out = Path(argv[0]), argv[1], Path(argv[2])
    try:
        result = export(folder, model)
    except Exception as exc:  # noqa: BLE001 - report any exporter failure in one line
        print(f"export of {model} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
