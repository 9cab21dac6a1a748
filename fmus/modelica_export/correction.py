"""The correction of modelica 0.0.205's flattener, applied to its flat model in-process.

Run under the exporter's interpreter (Python >= 3.12 with ``modelica==0.0.205``), not
imported by the project.  What the flattener does wrong on this package, each checked by
``tests/plant/test_modelica_export.py::test_flattener_still_needs_the_correction`` (which
fails once upstream changes it, so that the correction can be dropped):

1. an array binding ``Real q0[2] = {a, b}``, ``M_h[2, 2] = [a, b; c, d]``, or a modifier
   ``friction(Fc = {...})`` is given to every element whole (each element's binding is the
   ``Array`` / ``Matrix`` / ``if c then {..} else {..}``), and an element-wise binding of
   arrays ``q0 = posture_deg*(pi/180)`` or ``q[2] = q0 + theta`` keeps the unsubscripted
   array names;
2. names inside an array or matrix literal in a component's equation
   (``M = [a1 + ..., ...]`` in ``robot``) are not qualified with the component's name and
   keep their subscript nodes (``q[2]`` as ``Subscript(Ref(q), 2)``).

The fix: an element ``x[i]`` or ``x[i, j]`` takes element (i) / (i, j) of its binding
(literals are indexed, array names subscripted, element-wise operators distributed, ``fill``
and ``zeros`` reduced); an unqualified name that is not a variable is qualified with the
component prefix of a qualified name in the same equation (the one that makes it a
variable); a subscript with literal indices becomes the element's name.
"""
from __future__ import annotations

import dataclasses
import re

from modelica.ir import nodes as ir

_ELEMENT = re.compile(r"^(?P<base>.+)\[(?P<idx>[0-9, ]+)\]$")


class CorrectionError(RuntimeError):
    """A binding or equation the correction cannot make scalar (named)."""


def _index(name: str):
    m = _ELEMENT.match(name)
    if not m:
        return name, ()
    return m.group("base"), tuple(int(i) for i in m.group("idx").split(","))


def _element_name(base: str, idx) -> str:
    return f"{base}[{', '.join(str(i) for i in idx)}]"


class Corrector:
    """The correction over one flat model (``apply`` returns the corrected copy)."""

    def __init__(self, flat):
        self.flat = flat
        self.names = {v.name for v in flat.variables}
        self.arrays = {}
        for name in self.names:
            base, idx = _index(name)
            if idx:
                self.arrays.setdefault(base, set()).add(idx)

    # ---- element selection ------------------------------------------------------------
    def element(self, node, idx, where):
        """Element ``idx`` of the array-valued expression ``node`` (scalars pass through)."""
        if not idx:
            return node
        match node:
            case ir.Array(elements=els):
                return self.element(els[idx[0] - 1], idx[1:], where)
            case ir.Matrix(rows=rows):
                if len(idx) != 2:
                    raise CorrectionError(f"{where}: matrix literal indexed by {idx}")
                return rows[idx[0] - 1][idx[1] - 1]
            case ir.Ref() if node.name in self.arrays:
                return ir.Ref(parts=node.parts[:-1] + (_element_name(node.parts[-1], idx),))
            case ir.Ref() | ir.RealLiteral() | ir.IntLiteral() | ir.BoolLiteral():
                return node
            case ir.Binary(op=op, lhs=lhs, rhs=rhs) if op in ("+", "-", "*", "/", ".*", "./", ".+", ".-"):
                if op == "*" and self._is_array(lhs) and self._is_array(rhs):
                    raise CorrectionError(f"{where}: a product of two arrays is not element-wise")
                scalar_op = op.lstrip(".")
                return ir.Binary(op=scalar_op, lhs=self.element(lhs, idx, where),
                                 rhs=self.element(rhs, idx, where))
            case ir.Binary(op="^", lhs=lhs, rhs=rhs):
                return ir.Binary(op="^", lhs=self.element(lhs, idx, where), rhs=rhs)
            case ir.Unary(op=op, operand=x):
                return ir.Unary(op=op, operand=self.element(x, idx, where))
            case ir.IfExpr(condition=c, then=a, otherwise=b):
                return ir.IfExpr(condition=c, then=self.element(a, idx, where),
                                 otherwise=self.element(b, idx, where))
            case ir.Call(name="fill", args=(value, *_)):
                return value
            case ir.Call(name="zeros"):
                return ir.IntLiteral(value=0)
            case ir.Call(name="ones"):
                return ir.IntLiteral(value=1)
            case ir.Call(name=fn, args=(x,)) if fn in ("sin", "cos", "exp", "abs", "sqrt"):
                return ir.Call(name=fn, args=(self.element(x, idx, where),))
        raise CorrectionError(f"{where}: cannot take element {idx} of {node!r}")

    def _is_array(self, node) -> bool:
        match node:
            case ir.Array() | ir.Matrix():
                return True
            case ir.Ref():
                return node.name in self.arrays
            case ir.Binary(lhs=lhs, rhs=rhs):
                return self._is_array(lhs) or self._is_array(rhs)
            case ir.Unary(operand=x):
                return self._is_array(x)
            case ir.IfExpr(then=a, otherwise=b):
                return self._is_array(a) or self._is_array(b)
            case ir.Call(name=fn) if fn in ("fill", "zeros", "ones"):
                return True
        return False

    # ---- names ----------------------------------------------------------------------
    def qualify(self, node, prefixes, where):
        """Qualify unqualified names, turn literal subscripts into element names."""
        q = lambda x: self.qualify(x, prefixes, where)  # noqa: E731
        match node:
            case ir.Ref():
                if node.name in self.names or node.name in self.arrays or len(node.parts) > 1:
                    return node
                hits = [p for p in prefixes
                        if f"{p}.{node.name}" in self.names or f"{p}.{node.name}" in self.arrays]
                if len(hits) == 1:
                    return ir.Ref(parts=tuple(hits[0].split(".")) + node.parts)
                if not hits:
                    return node  # e.g. time
                raise CorrectionError(f"{where}: {node.name} is ambiguous among {hits}")
            case ir.Subscript(base=base, indices=indices):
                base = q(base)
                if all(isinstance(i, ir.IntLiteral) for i in indices):
                    name = _element_name(base.parts[-1], [i.value for i in indices])
                    return ir.Ref(parts=base.parts[:-1] + (name,))
                return ir.Subscript(base=base, indices=tuple(q(i) for i in indices))
            case ir.Binary(op=op, lhs=lhs, rhs=rhs):
                return ir.Binary(op=op, lhs=q(lhs), rhs=q(rhs))
            case ir.Unary(op=op, operand=x):
                return ir.Unary(op=op, operand=q(x))
            case ir.IfExpr(condition=c, then=a, otherwise=b):
                return ir.IfExpr(condition=q(c), then=q(a), otherwise=q(b))
            case ir.Call(name=fn, args=args, named=named):
                return ir.Call(name=fn, args=tuple(q(a) for a in args),
                               named=tuple((k, q(v)) for k, v in named))
            case ir.Array(elements=els):
                return ir.Array(elements=tuple(q(e) for e in els))
            case ir.Matrix(rows=rows):
                return ir.Matrix(rows=tuple(tuple(q(e) for e in r) for r in rows))
        return node

    @staticmethod
    def _prefixes(*nodes):
        out = set()

        def walk(n):
            if isinstance(n, ir.Ref) and len(n.parts) > 1:
                for k in range(1, len(n.parts)):
                    out.add(".".join(n.parts[:k]))
            elif dataclasses.is_dataclass(n) and not isinstance(n, type):
                for f in dataclasses.fields(n):
                    v = getattr(n, f.name)
                    for x in (v if isinstance(v, tuple) else (v,)):
                        if isinstance(x, tuple):
                            for y in x:
                                walk(y)
                        else:
                            walk(x)
        for n in nodes:
            walk(n)
        return sorted(out, key=len, reverse=True)[:1] or []

    # ---- the flat model ----------------------------------------------------------------
    def variable(self, v):
        base, idx = _index(v.name)
        scope = v.name.rsplit(".", 1)[0] if "." in base else ""
        changes = {}
        for attr in ("binding", "start"):
            node = getattr(v, attr)
            if node is None:
                continue
            where = f"{v.name} ({attr})"
            node = self.qualify(node, [scope] if scope else [], where)
            node = self.element(node, idx, where) if self._is_array(node) else node
            changes[attr] = node
        return dataclasses.replace(v, **changes) if changes else v

    def equation(self, eq, k):
        match eq:
            case ir.Equal(lhs=lhs, rhs=rhs):
                where = f"equation {k}"
                prefixes = self._prefixes(lhs, rhs)
                lhs, rhs = self.qualify(lhs, prefixes, where), self.qualify(rhs, prefixes, where)
                if isinstance(lhs, ir.Ref) and self._is_array(rhs):
                    _, idx = _index(lhs.parts[-1])
                    rhs = self.element(rhs, idx, where)
                return dataclasses.replace(eq, lhs=lhs, rhs=rhs)
        return eq

    def apply(self):
        variables = tuple(self.variable(v) for v in self.flat.variables)
        equations = tuple(self.equation(e, k) for k, e in enumerate(self.flat.equations))
        return dataclasses.replace(self.flat, variables=variables, equations=equations)


def correct(flat):
    """The flat model with the flattener's array bindings and unqualified names fixed."""
    return Corrector(flat).apply()
