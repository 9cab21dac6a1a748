"""The plant exported from its Modelica source (modelica/ArmExo) as FMI 2.0 / 3.0 CS FMUs.

The exporter is the pure-Python Modelica front end ``modelica==0.0.205``
(requirements-export.txt), which needs Python >= 3.12: it runs as a subprocess of that
interpreter (``fmus/modelica_export/export.py``: parse, flatten, the flattener correction,
causalise, emit C) and writes one JSON file with the generated C and the variable table.
This module writes the C tables and ``modelDescription.xml`` from it and compiles the C
with the project's FMI framework (``fmus/framework``; glue in ``fmus/ArmExoModelica``), the
same fixed-step RK4 grid and the same time/state-machine behaviour as the C FMU.

Files: ``fmus/build/ArmExoPlant_modelica.fmu`` (FMI 2.0), ``ArmExoPlant_modelica_fmi3.fmu``
(FMI 3.0), ``ArmExoPlant3_modelica.fmu`` (three joints, FMI 2.0).  The exported C is cached
in ``fmus/build/modelica/`` under a SHA-256 of the Modelica sources and the exporter files.

Variables: ``rk4_step`` (the shell's), every independent parameter of the model under its
flat name (``arm.M_h[1,1]``, ``friction.Fs[2]``, ...; Integer sizes excluded), the model's
inputs ``tau_m[j]``, its outputs ``theta[j]``, ``tau_h[j]``, ``omega[j]`` and, as outputs
for diagnosis, ``tau_act[j]``, ``friction.tau_f[j]``, ``friction.z[j]``, ``theta_link[j]``
and ``arm.theta[j]``; units, descriptions, start values and min from the model.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path
from xml.sax.saxutils import escape

from .build import (BUILD_DIR, CFLAGS, FMI_HEADERS, FRAMEWORK_DIR, BuildError, _fmi_header_dir,
                    pack_fmu)
from .variables import UNITS

PACKAGE_DIR = Path(__file__).resolve().parent
REPO = PACKAGE_DIR.parent
MODELICA_DIR = REPO / "modelica" / "ArmExo"
EXPORT_DIR = PACKAGE_DIR / "modelica_export"
GLUE_DIR = PACKAGE_DIR / "ArmExoModelica"
CACHE_DIR = BUILD_DIR / "modelica"
EXPORTER_VERSION = "0.0.205"
MODELS = {2: "ArmExo.ArmExoPlant", 3: "ArmExo.ArmExoPlant3"}
#: model variables exposed as outputs beside the contract's (the C FMU's diagnosis outputs)
EXTRA_OUTPUTS = ("tau_act", "friction.tau_f", "friction.z", "theta_link", "arm.theta")


#: The effect switches of the model: each effect's ``on`` (computed from its parameters, see
#: docs/plant.md) and the tilt of the plane.  The build compiles the generated rhs once per
#: combination of their values with the switches as constants (``md_rhs_sw`` inlined into one
#: RK4 loop per combination, over the states that combination can change), so that the C
#: compiler drops what they switch off; the FMU takes the loop of the combination its
#: parameters give (:func:`switch_values` lists the switch parameters each sets).
SWITCHES = ("actuator_lag.on", "transmission_compliance.on", "interface_compliance.on",
            "torque_sensor_lag.on", "robot.tilted")


def switch_values(bits, n: int) -> dict:
    """The value of every switch parameter when the switches ``SWITCHES`` have the values
    ``bits`` (0 or 1 each): they and the ones the model derives from them (``cuff_rigid =
    not interface_compliance.on``, ``robot.Jm_on_link[j] = not transmission_compliance.on``).
    A parameter set whose switch parameters match no combination runs the generic loop."""
    v = {k: float(b) for k, b in zip(SWITCHES, bits, strict=True)}
    v["cuff_rigid"] = 1.0 - v["interface_compliance.on"]
    for j in range(1, n + 1):
        v[f"robot.Jm_on_link[{j}]"] = 1.0 - v["transmission_compliance.on"]
    return v


class ExporterUnavailable(BuildError):
    """No Python >= 3.12 with modelica==0.0.205 (the build falls back to the C plant)."""


def identifier(n: int = 2) -> str:
    """Model identifier: ``ArmExoPlant_modelica`` (2 joints), ``ArmExoPlant3_modelica``."""
    return "ArmExoPlant_modelica" if n == 2 else f"ArmExoPlant{n}_modelica"


def fmu_name(fmi_version: int = 2, n: int = 2) -> str:
    return f"{identifier(n)}{'_fmi3' if fmi_version == 3 else ''}.fmu"


def _candidates():
    env = os.environ.get("ARMEXO_EXPORT_PYTHON")
    if env:
        yield env
        return
    try:
        root = subprocess.run(["pyenv", "root"], capture_output=True, text=True, timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        root = ""
    if root:
        for d in sorted(Path(root, "versions").glob("3.1[2-9]*")):
            yield str(d / "bin" / "python")
    for name in ("python3.12", "python3.13", "python3.14"):
        found = shutil.which(name)
        if found:
            yield found


_CHECK = ("import sys, importlib.metadata as m; assert sys.version_info >= (3, 12); "
          "print(m.version('modelica'))")


def find_exporter() -> str:
    """The interpreter that runs the exporter (``$ARMEXO_EXPORT_PYTHON``, else a pyenv
    3.12+ or python3.12/3.13 on PATH with modelica==0.0.205 installed).

    Raises
    ------
    ExporterUnavailable
        None found (one line saying what is missing).
    """
    seen = []
    for python in _candidates():
        if not Path(python).exists():
            continue
        try:
            proc = subprocess.run([python, "-c", _CHECK], capture_output=True, text=True, timeout=60)
        except (OSError, subprocess.SubprocessError):
            continue
        version = proc.stdout.strip()
        if proc.returncode == 0 and version == EXPORTER_VERSION:
            return python
        seen.append(f"{python} ({'modelica ' + version if proc.returncode == 0 else 'no modelica'})")
    raise ExporterUnavailable(
        f"no Python >= 3.12 with modelica=={EXPORTER_VERSION} (checked: {', '.join(seen) or 'none'}); "
        "install it with `python3.12 -m pip install -r requirements-export.txt` or set "
        "ARMEXO_EXPORT_PYTHON")


def source_hash() -> str:
    """SHA-256 over the Modelica package and the exporter files (the cache key)."""
    h = hashlib.sha256(EXPORTER_VERSION.encode())
    files = [(f, f.relative_to(MODELICA_DIR)) for f in
             sorted(MODELICA_DIR.rglob("*.mo")) + sorted(MODELICA_DIR.rglob("package.order"))]
    files += [(f, Path("modelica_export") / f.name) for f in sorted(EXPORT_DIR.glob("*.py"))]
    for f, name in files:
        h.update(str(name).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def export(n: int = 2, *, python: str | None = None, use_cache: bool = True) -> dict:
    """The exported model of n joints (the exporter's JSON, see modelica_export/export.py).

    Raises
    ------
    ExporterUnavailable
        No exporter interpreter.
    BuildError
        The export failed (its message).
    """
    if n not in MODELS:
        raise ValueError(f"the Modelica plants have n in {sorted(MODELS)}, got {n!r}")
    if not (MODELICA_DIR / "package.mo").is_file():
        raise ExporterUnavailable(f"the Modelica source {MODELICA_DIR} is missing (the exporter "
                                  "needs the repository's modelica/ArmExo)")
    key = source_hash()[:16]
    cached = CACHE_DIR / f"{MODELS[n]}-{key}.json"
    if use_cache and cached.exists():
        return json.loads(cached.read_text())
    python = python or find_exporter()
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    tmp = CACHE_DIR / f".{MODELS[n]}.{os.getpid()}.json"
    proc = subprocess.run([python, str(EXPORT_DIR / "export.py"), str(MODELICA_DIR), MODELS[n], str(tmp)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        tmp.unlink(missing_ok=True)
        raise BuildError(f"exporting {MODELS[n]} failed: {proc.stderr.strip()}")
    os.replace(tmp, cached)
    for old in CACHE_DIR.glob(f"{MODELS[n]}-*.json"):  # exports of older sources
        if old != cached:
            old.unlink(missing_ok=True)
    return json.loads(cached.read_text())


def _fmi_name(name: str) -> str:
    return name.replace(", ", ",")


def table(exported: dict) -> dict:
    """The FMU's variables (value reference order) from the exported model."""
    variables = [{"name": "rk4_step", "causality": "parameter", "unit": "s", "start": 1e-5, "min": 0.0,
                  "description": "Fixed step of the internal classical RK4 solver (the FMU shell's)"}]
    params = []
    for p in exported["parameters"]:
        if p["independent"] and p["type"] == "Real":
            params.append(p)
            variables.append({"name": _fmi_name(p["name"]), "causality": "parameter", "unit": p["unit"],
                              "start": p["start"], "min": p["min"], "description": p["description"],
                              "slot": p["slot"]})
    for k, u in enumerate(exported["inputs"]):
        variables.append({"name": _fmi_name(u["name"]), "causality": "input", "unit": u["unit"],
                          "start": 0.0, "min": None, "description": u["description"], "input": k})
    var = exported["variables"]
    names = [v for v, a in var.items() if a["causality"] == "output"]
    for base in EXTRA_OUTPUTS:
        names += [v for v in var if v.startswith(base + "[")]
    for name in names:
        if name not in exported["observed"]:
            raise BuildError(f"output {name} is not observed by the exported code")
        variables.append({"name": _fmi_name(name), "causality": "output", "unit": var[name]["unit"],
                          "start": None, "min": None, "description": var[name]["description"],
                          "slot": exported["observed"][name]})
    guid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, exported["model"] + exported["c"]
                                + repr([(v["name"], v["start"]) for v in variables]))) + "}"
    return {"variables": variables, "guid": guid}


def _c(x: float) -> str:
    return repr(float(x))


def _cstr(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def header_text(exported: dict, t: dict, ident: str) -> str:
    v = t["variables"]
    lines = [f"/* GENERATED by fmus/modelica_build.py from {exported['model']}: do not edit. */",
             "#ifndef ARMEXO_MODELICA_VARIABLES_H", "#define ARMEXO_MODELICA_VARIABLES_H", "",
             f'#define MODEL_IDENTIFIER_STRING "{ident}"', f'#define INSTANTIATION_TOKEN "{t["guid"]}"',
             f"#define N_VR {len(v)}", f"#define NX {len(exported['states'])}",
             f"#define NP {exported['n_parameters']}", f"#define NU {len(exported['inputs'])}",
             f"#define NOBS {exported['n_observed']}", f"#define NROT {_equations(exported)[1]}", f"#define NHOIST {max(1, len(_equations(exported)[2]))}", "",
             "enum { CAUS_PARAMETER = 0, CAUS_INPUT = 1, CAUS_OUTPUT = 2 };",
             "enum { vr_rk4_step = 0 };", "",
             "static const char *const VR_NAME[N_VR] = {", *(f"    {_cstr(x['name'])}," for x in v), "};",
             "static const unsigned char VR_CAUSALITY[N_VR] = {",
             *(f"    CAUS_{x['causality'].upper()}," for x in v), "};",
             "static const double VR_START[N_VR] = {",
             *(f"    {_c(x['start']) if x['start'] is not None else '0.0'}," for x in v), "};", ""]
    par = [(i, x) for i, x in enumerate(v) if "slot" in x and x["causality"] == "parameter"]
    lines += [f"#define N_PARAM_VR {len(par)}",
              "static const int PARAM_VR[N_PARAM_VR] = {" + ", ".join(str(i) for i, _ in par) + "};",
              "static const int PARAM_SLOT[N_PARAM_VR] = {" + ", ".join(str(x["slot"]) for _, x in par) + "};",
              "static const int PARAM_HAS_MIN[N_PARAM_VR] = {"
              + ", ".join("1" if x["min"] is not None else "0" for _, x in par) + "};",
              "static const double PARAM_MIN[N_PARAM_VR] = {"
              + ", ".join(_c(x["min"]) if x["min"] is not None else "0.0" for _, x in par) + "};"]
    inp = [i for i, x in enumerate(v) if x["causality"] == "input"]
    lines += ["static const int INPUT_VR[NU] = {" + ", ".join(map(str, inp)) + "};"]
    out = [(i, x) for i, x in enumerate(v) if x["causality"] == "output"]
    lines += [f"#define N_OUTPUT_VR {len(out)}",
              "static const int OUTPUT_VR[N_OUTPUT_VR] = {" + ", ".join(str(i) for i, _ in out) + "};",
              "static const int OUTPUT_SLOT[N_OUTPUT_VR] = {" + ", ".join(str(x["slot"]) for _, x in out) + "};"]
    ps = exported["parameters"]
    lines += ["static const double P_START[NP] = {"
              + ", ".join(_c(p.get("start") or 0.0) if p["independent"] else "0.0" for p in ps) + "};",
              "static const char *const P_NAME[NP] = {" + ", ".join(_cstr(p["name"]) for p in ps) + "};",
              "static const double X_START[NX] = {" + ", ".join(_c(s["start"]) for s in exported["states"]) + "};",
              "static const char *const X_NAME[NX] = {"
              + ", ".join(_cstr(s["name"]) for s in exported["states"]) + "};", "", "#endif", ""]
    return "\n".join(lines)


def _n_joints(exported: dict) -> int:
    return len([v for v in exported["variables"] if v.startswith("tau_m[")])


def _switched_rhs(c: str, exported: dict) -> tuple[str, list[str], list[int]]:
    """The generated rhs (from ``c``) as ``md_rhs_sw``: always inlined, each switch parameter
    read from an argument instead of ``p``; (its text, the switch names in argument order,
    their slots in ``p``), or ("", [], []) when the model lacks a switch (then no variants).

    Raises
    ------
    BuildError
        The rhs reads a switch otherwise than ``SYMBOL = p[SLOT];`` (the exporter changed).
    """
    symbols = exported.get("symbols", {})
    slots = {p["name"]: p["slot"] for p in exported["parameters"]}
    names = list(switch_values([0] * len(SWITCHES), _n_joints(exported)))
    if any(k not in slots or k not in symbols for k in names):
        return "", [], []
    start = c.index("void rhs(")
    end = c.index("\n}\n", start) + 3
    body = c[start:end]
    head = "void rhs(double t, const double *y, const double *p, double *w, double *dy) {"
    if not body.startswith(head):
        raise BuildError("the generated rhs does not start with '" + head + "': the exporter's output changed")
    body = ("static inline __attribute__((always_inline)) void md_rhs_sw(double t, const double *y, "
            "const double *p, double *w, double *dy, "
            + ", ".join(f"const double sw{k}" for k in range(len(names))) + ") {" + body[len(head):])
    for k, name in enumerate(names):
        line = f"    {symbols[name]} = p[{slots[name]}];"
        if line not in body:
            raise BuildError(f"the generated rhs reads the switch {name} otherwise than "
                             f"'{line.strip()}': the exporter's output changed")
        body = body.replace(line, f"    {symbols[name]} = sw{k};")
    return body, names, [slots[k] for k in names]


def active_states(rhs: str, exported: dict, values: dict) -> list[int]:
    """States whose derivative can be nonzero when the switch parameters have ``values``: all
    but those assigned ``SWITCH ? ... : 0.0`` with a switch that is 0 there (read from the C
    text of the rhs; a state not matched is kept)."""
    import re

    symbols = exported.get("symbols", {})
    off = {symbols[k] for k, v in values.items() if v == 0.0 and k in symbols}
    active = []
    for k in range(len(exported["states"])):
        m = re.search(rf"^    dy\[{k}\] = ([A-Za-z0-9_]+);$", rhs, re.M)
        if m:
            a = re.search(rf"^    {re.escape(m.group(1))} = ([A-Za-z0-9_]+) \? .* : 0\.0;$", rhs, re.M)
            if a and a.group(1) in off:
                continue
        active.append(k)
    return active


def _rk4_loop(name: str, args: str, active: list[int]) -> list[str]:
    """C of ``static int name(Snapshot *s, long long n)``: classical RK4 as solver.h's with
    ``md_rhs_sw(..., args)`` inlined, over the states ``active`` only (the others have
    derivative 0 and keep their values exactly, as in a loop over all states)."""
    def each(fmt):
        return "        " + " ".join(fmt.format(i=i) for i in active)
    return [
        f"static int {name}(Snapshot *s, long long n) {{",
        "    const double h = s->h, h2 = 0.5 * s->h, h6 = s->h / 6.0;",
        "    const double *p = s->d.p;",
        "    double *w = s->d.w;",
        "    double x[NX], k1[NX], k2[NX], k3[NX], k4[NX], xt[NX];",
        "    int i, bad = -1;",
        "    long long k;",
        "    for (i = 0; i < NX; i++) x[i] = xt[i] = s->x[i];",
        "    for (k = 0; k < n; k++) {",
        f"        md_rhs_sw(0.0, x, p, w, k1, {args});",
        each("xt[{i}] = x[{i}] + h2 * k1[{i}];"),
        f"        md_rhs_sw(0.0, xt, p, w, k2, {args});",
        each("xt[{i}] = x[{i}] + h2 * k2[{i}];"),
        f"        md_rhs_sw(0.0, xt, p, w, k3, {args});",
        each("xt[{i}] = x[{i}] + h * k3[{i}];"),
        f"        md_rhs_sw(0.0, xt, p, w, k4, {args});",
        "        double acc = 0.0; /* NaN iff some x[i] is Inf or NaN */",
        each("x[{i}] += h6 * (k1[{i}] + 2.0 * (k2[{i}] + k3[{i}]) + k4[{i}]); acc += 0.0 * x[{i}];"),
        "        if (!(acc == 0.0)) {",
        each("if (bad < 0 && !isfinite(x[{i}])) bad = {i};"),
        "            break;",
        "        }",
        "    }",
        "    s->nSteps += k;",
        "    s->time = s->startTime + (double)s->nSteps * h;",
        "    for (i = 0; i < NX; i++) s->x[i] = x[i];",
        "    return bad;",
        "}", ""]


def _calls(text: str, fn: str):
    """(start, end, argument) of every call ``fn(...)`` in ``text`` (balanced parentheses)."""
    import re

    for m in re.finditer(rf"(?<![A-Za-z0-9_]){fn}\(", text):
        depth, i = 1, m.end()
        while depth:
            depth += {"(": 1, ")": -1}.get(text[i], 0)
            i += 1
        yield m.start(), i, text[m.end():i - 1]


def _rotated(body: str, slots: dict) -> str:
    """``body`` (one C function) with sin(a) and cos(a) taken from one md_sincos per distinct
    argument a: the first use in a call evaluates it (into locals), the others reuse it (the
    generated code assigns every variable once, so the same text is the same value)."""
    out, pos, used = [], 0, []
    calls = sorted([(a, b, arg, fn) for fn in ("sin", "cos") for a, b, arg in _calls(body, fn)])
    for a, b, arg, fn in calls:
        k = slots.setdefault(arg, len(slots))
        if k not in used:
            used.append(k)
        out += [body[pos:a], f"MD_{fn.upper()}({k}, {arg})"]
        pos = b
    text = "".join(out) + body[pos:]
    if used:
        brace = text.index("{") + 1
        decl = "".join(f"\n    double md_s{k}, md_c{k}; int md_have{k} = 0;" for k in used)
        text = text[:brace] + decl + text[brace:]
    return text


def _balanced(text: str, i: int) -> int:
    """Index after the parenthesis that closes the one at ``text[i]``."""
    depth = 0
    while True:
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        i += 1
        if depth == 0:
            return i


def _exp_tails(body: str, hoisted: list[str]) -> str:
    """``body`` (the rhs) with every branch ``A + (B) * exp(E)`` whose A and B read parameters
    only (A one, B a parenthesised expression of them) written ``md_add_exp(A, (B), E, cut)``,
    the cut a parameter-only expression appended to ``hoisted`` (in terms of ``p``): the
    value is the same, exp() is skipped where it cannot change the sum (LuGre's Stribeck
    curve Fc + (Fs - Fc) exp(-(w/ws)^2) at speed, as the C FMU does).  Only a whole branch
    or right-hand side is matched (after ``= ``, ``? `` or ``: ``, before ``;``, `` :`` or
    `` ?``), so that no operator of higher precedence binds A or the product."""
    import re

    params = dict(re.findall(r"^    ([A-Za-z_][A-Za-z0-9_]*) = (p\[\d+\]);$", body, re.M))
    name = r"[A-Za-z_][A-Za-z0-9_]*"
    out, pos = [], 0
    for m in re.finditer(rf"(?<=[=?:] )({name}) \+ \(", body):
        if m.start() < pos or m.group(1) not in params:
            continue
        b_end = _balanced(body, m.end() - 1)
        b_text = body[m.end() - 1:b_end]
        if not body.startswith(" * exp(", b_end):
            continue
        e_open = b_end + len(" * exp")
        e_end = _balanced(body, e_open)
        if not re.match(r" :|;| \?", body[e_end:e_end + 2]):
            continue
        refs = re.findall(name, b_text)
        if not refs or any(r not in params for r in refs) or re.search(r"[^A-Za-z0-9_ +\-*/().]", b_text):
            continue
        sub = lambda t: re.sub(name, lambda r: params[r.group(0)], t)  # noqa: E731
        a_p, b_p = params[m.group(1)], sub(b_text)
        hoisted.append(f"md_exp_cut({a_p}, {b_p})")
        out += [body[pos:m.start()],
                f"md_add_exp({m.group(1)}, {b_text}, {body[e_open + 1:e_end - 1]}, p[NP + NU + {len(hoisted) - 1}])"]
        pos = e_end
    return "".join(out) + body[pos:]


#: a + b exp(e) and the cut below which it rounds to a (see _exp_tails)
_ADD_EXP = """/* a + b exp(e), with exp() skipped where the sum rounds to a exactly: for a > 0 and
   e < cut = log(a / |b|) - 56 log 2, |b exp(e)| < a 2^-56 (with exp's and log's rounding,
   below a 2^-55), less than half an ulp of a, so a + b exp(e) == a in round-to-nearest.
   cut = -inf (never skipped) unless a > 0 and b != 0 are finite. */
static inline double md_exp_cut(double a, double b) {
    return (a > 0.0 && b != 0.0 && isfinite(a) && isfinite(b)) ? log(a / fabs(b)) - 56.0 * 0.6931471805599453 : -INFINITY;
}
static inline double md_add_exp(double a, double b, double e, double cut) {
    return e < cut ? a : a + b * exp(e);
}
"""


def _equations(exported: dict) -> tuple[str, int, list[str]]:
    """(the generated C with rhs's sin/cos rotated and its exp tails cut, NROT: the number
    of rotation slots, the parameter-only expressions hoisted out of rhs: p[NP + NU + k])."""
    c = exported["c"]
    start = c.index("void rhs(")
    end = c.index("\n}\n", start) + 3
    slots: dict = {}
    hoisted: list[str] = []
    c = c[:start] + _rotated(_exp_tails(c[start:end], hoisted), slots) + c[end:]
    return c, len(slots), hoisted


_ROTATION = """/* sin and cos of an angle from an exact libm pair at a nearby reference angle (one per
   distinct argument, in the workspace): sin(r + d) = s_r cos d + c_r sin d with the Taylor
   series sin d = d - d^3/6, cos d = 1 - d^2/2 + d^4/24 for |d| <= 1e-4 rad (the terms left
   out are below 8.4e-23 and 1.4e-27, far below the rounding of the result), a new exact
   reference when |d| > 1e-4 (or at the first call: a NaN reference).  What the C FMU does
   with its step-start rotation; it replaces the sin/cos evaluations of an RK4 step by
   polynomials.  MD_SIN(k, a) and MD_COS(k, a) evaluate the pair once per call of the
   function (locals md_s<k>, md_c<k>). */
static inline void md_sincos(double *slot, double a, double *s, double *c) {
    const double d = a - slot[0];
    if (!(fabs(d) <= 1e-4)) {
        slot[0] = a; slot[1] = sin(a); slot[2] = cos(a);
        *s = slot[1]; *c = slot[2];
        return;
    }
    const double d2 = d * d;
    const double sd = d - d * d2 * (1.0 / 6.0);
    const double cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
    *s = slot[1] * cd + slot[2] * sd;
    *c = slot[2] * cd - slot[1] * sd;
}
#define MD_SIN(k, a) (md_have##k ? md_s##k : (md_sincos(w + MD_ROT_OFFSET + 3 * (k), (a), &md_s##k, &md_c##k), md_have##k = 1, md_s##k))
#define MD_COS(k, a) (md_have##k ? md_c##k : (md_sincos(w + MD_ROT_OFFSET + 3 * (k), (a), &md_s##k, &md_c##k), md_have##k = 1, md_c##k))
"""


def _pruned_observe(c: str, keep: set[int]) -> str:
    """``c`` with observe() storing only the slots in ``keep`` (the FMU's outputs): the C
    compiler then drops every computation that fed only the others."""
    import re

    start = c.index("void observe(")
    end = c.index("\n}\n", start) + 3
    body = c[start:end]
    stores = re.findall(r"^    out\[(\d+)\] = [^;]*;$", body, re.M)
    if not stores or not keep <= {int(k) for k in stores}:
        raise BuildError("the generated observe() does not store every output slot as "
                         "'out[k] = ...;': the exporter's output changed")
    body = re.sub(r"^    out\[(\d+)\] = [^;]*;\n",
                  lambda m: m.group(0) if int(m.group(1)) in keep else "", body, flags=re.M)
    return c[:start] + body + c[end:]


def generated_c(exported: dict) -> str:
    """The C the FMU compiles (``generated.c``): the exporter's code with rhs's sin/cos
    rotated and observe() pruned to the FMU's outputs, ``md_rhs_sw`` (rhs with the switches
    as arguments), one RK4 loop per switch combination (``MD_RK4``, chosen by
    ``md_variant(p)``) and a generic loop (``md_rk4_generic``, the switches read from ``p``),
    and ``md_dependent`` (the dependent parameters)."""
    import itertools

    body = [f"    p[{k}] = {exported['parameters'][k]['c']};  /* {exported['parameters'][k]['name']} */"
            for k in exported["dependent_order"]]
    c, nrot, hoisted = _equations(exported)
    c = _pruned_observe(c, {x["slot"] for x in table(exported)["variables"] if x["causality"] == "output"})
    rhs, names, slots = _switched_rhs(c, exported)
    n = _n_joints(exported)
    loops, table_, values = [], [], []
    if rhs:
        for k, bits in enumerate(itertools.product((0, 1), repeat=len(SWITCHES))):
            v = switch_values(bits, n)
            values.append([v[x] for x in names])
            on = ", ".join(f"{x}={int(v[x])}" for x in SWITCHES)
            loops += [f"/* variant {k}: {on} */",
                      *_rk4_loop(f"md_rk4_v{k}", ", ".join(repr(v[x]) for x in names), active_states(rhs, exported, v))]
            table_.append(f"md_rk4_v{k}")
        generic = _rk4_loop("md_rk4_generic", ", ".join(f"p[{k}]" for k in slots), list(range(len(exported["states"]))))
    else:  # no switches to specialise on: the generated rhs, always inlined, over every state
        start = c.index("void rhs(")
        rhs = "static inline __attribute__((always_inline)) void md_rhs_sw(" + c[start + len("void rhs("):c.index("\n}\n", start) + 3]
        generic = _rk4_loop("md_rk4_generic", "", list(range(len(exported["states"]))))
        generic = [line.replace(", )", ")") for line in generic]
    nv = len(table_)
    select = ["/* The loop of the switch combination the parameters give (-1: none, the generic loop). */",
              f"#define MD_NVARIANT {nv}"]
    if nv:
        select.insert(0, "#ifndef MD_FORCE_GENERIC  /* -DMD_FORCE_GENERIC (tests): the generic loop only */")
        select += [f"static const int MD_SW_SLOT[{len(slots)}] = {{" + ", ".join(map(str, slots)) + "};",
                   f"static const double MD_SW_VALUE[MD_NVARIANT][{len(slots)}] = {{",
                   *("    {" + ", ".join(repr(x) for x in row) + "}," for row in values), "};",
                   "static int (*const MD_RK4[MD_NVARIANT])(Snapshot *, long long) = {"
                   + ", ".join(table_) + "};",
                   "static int md_variant(const double *p) {",
                   "    for (int v = 0; v < MD_NVARIANT; v++) {",
                   "        int k = 0;",
                   f"        while (k < {len(slots)} && p[MD_SW_SLOT[k]] == MD_SW_VALUE[v][k]) k++;",
                   f"        if (k == {len(slots)}) return v;",
                   "    }",
                   "    return -1;",
                   "}",
                   "#else",
                   "static int (*const MD_RK4[1])(Snapshot *, long long) = {0};",
                   "static int md_variant(const double *p) { (void)p; return -1; }",
                   "#endif"]
    else:
        select += ["static int (*const MD_RK4[1])(Snapshot *, long long) = {0};",
                   "static int md_variant(const double *p) { (void)p; return -1; }"]
    return "\n".join([
        f"/* The equations of {exported['model']}, generated by {exported['generator']}. */",
        "#if defined(__GNUC__)", "#pragma GCC diagnostic ignored \"-Wunused-parameter\"",
        "#pragma GCC diagnostic ignored \"-Wunused-variable\"",
        "#pragma GCC diagnostic ignored \"-Wunused-but-set-variable\"",
        "#pragma GCC diagnostic ignored \"-Wunused-function\"", "#endif",
        "#include <math.h>", f"#define MD_ROT_OFFSET (NOBS + 1)", _ROTATION, _ADD_EXP,
        c, "/* The generated rhs with the effect switches as arguments (constants in the loops). */", rhs,
        "/* The RK4 loops, one per combination of the switches (the states it can change only). */",
        *(["#ifndef MD_FORCE_GENERIC", *loops, "#endif"] if loops else []), *generic, *select, "",
        "/* The dependent (calculated) parameters, from the model's bindings, in evaluation order. */",
        "static void md_dependent(double *p) {", *body,
        "    /* parameter-only expressions of rhs, hoisted (after the inputs) */",
        *(f"    p[NP + NU + {k}] = {e};" for k, e in enumerate(hoisted)), "}", ""])


def _fmt(x) -> str:
    return repr(float(x))


def model_description_text(exported: dict, t: dict, ident: str, fmi_version: int) -> str:
    v = t["variables"]
    desc = escape(f"{exported['model']} exported from modelica/ArmExo by modelica {EXPORTER_VERSION} "
                  "(fixed-step RK4 in the project's FMI framework)")
    units = sorted({x["unit"] for x in v if x["unit"]})
    unit_lines = ["  <UnitDefinitions>"]
    for u in units:
        if u in UNITS:
            attrs = " ".join(f'{k}="{e}"' for k, e in UNITS[u].items())
            unit_lines.append(f'    <Unit name="{escape(u)}"><BaseUnit {attrs}/></Unit>')
        else:
            unit_lines.append(f'    <Unit name="{escape(u)}"/>')
    unit_lines.append("  </UnitDefinitions>")
    head = ['<?xml version="1.0" encoding="UTF-8"?>', "<fmiModelDescription",
            f'  fmiVersion="{fmi_version}.0"', f'  modelName="{exported["model"]}"',
            (f'  guid="{t["guid"]}"' if fmi_version == 2 else f'  instantiationToken="{t["guid"]}"'),
            f'  description="{desc}"', f'  generationTool="modelica {EXPORTER_VERSION} + fmus/modelica_build.py"',
            '  variableNamingConvention="structured"' + ('\n  numberOfEventIndicators="0">' if fmi_version == 2 else ">"), ""]
    if fmi_version == 2:
        head += [f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"'
                 ' canGetAndSetFMUstate="true" canNotUseMemoryManagementFunctions="true">',
                 "    <SourceFiles>", f'      <File name="{ident}_all.c"/>', "    </SourceFiles>",
                 "  </CoSimulation>", ""]
    else:
        head += [f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"'
                 ' canGetAndSetFMUState="true" canSerializeFMUState="false" hasEventMode="false"'
                 ' canReturnEarlyAfterIntermediateUpdate="false"/>', ""]
    out = head + unit_lines + ["", '  <DefaultExperiment startTime="0" stopTime="2" stepSize="0.001"/>', "",
                               "  <ModelVariables>"]
    if fmi_version == 3:
        out.append(f'    <Float64 name="time" valueReference="{len(v)}" causality="independent" '
                   'variability="continuous" unit="s" description="Simulation time"/>')
    for i, x in enumerate(v):
        variability = "fixed" if x["causality"] == "parameter" else "continuous"
        attrs = [f'name="{escape(x["name"])}"', f'valueReference="{i}"', f'causality="{x["causality"]}"',
                 f'variability="{variability}"']
        if x["causality"] == "parameter":
            attrs.append('initial="exact"')
        extra = []
        if x["causality"] != "output" and x["start"] is not None:
            extra.append(f'start="{_fmt(x["start"])}"')
        if x["unit"]:
            extra.append(f'unit="{escape(x["unit"])}"')
        if x["min"] is not None:
            extra.append(f'min="{_fmt(x["min"])}"')
        d = f'description="{escape(x["description"])}"'
        if fmi_version == 2:
            out.append(f"    <!-- index {i + 1} -->")
            out.append(f'    <ScalarVariable {" ".join(attrs)} {d}>')
            out.append(f'      <Real {" ".join(extra)}/>')
            out.append("    </ScalarVariable>")
        else:
            out.append(f'    <Float64 {" ".join(attrs + extra)} {d}/>')
    out += ["  </ModelVariables>", "", "  <ModelStructure>"]
    outs = [i for i, x in enumerate(v) if x["causality"] == "output"]
    if fmi_version == 2:
        out += ["    <Outputs>", *(f'      <Unknown index="{k + 1}"/>' for k in outs), "    </Outputs>",
                "    <InitialUnknowns>", *(f'      <Unknown index="{k + 1}"/>' for k in outs),
                "    </InitialUnknowns>"]
    else:
        out += [f'    <Output valueReference="{k}"/>' for k in outs]
        out += [f'    <InitialUnknown valueReference="{k}"/>' for k in outs]
    out += ["  </ModelStructure>", "", "</fmiModelDescription>", ""]
    return "\n".join(out)


_BUILD_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{ident}">
    <SourceFileSet language="C99">
      <SourceFile name="{ident}_all.c"/>
      <PreprocessorDefinition name="FMI_VERSION" value="3"/>
    </SourceFileSet>
  </BuildConfiguration>
</fmiBuildDescription>
"""


def build_fmu(out_dir=None, *, cc: str | None = None, fmi_version: int = 2, n: int = 2,
              exported: dict | None = None) -> Path:
    """Export (or take from the cache), compile and package one Modelica plant FMU.

    Parameters
    ----------
    out_dir : path, optional
        Folder of the FMU (default ``fmus/build/``).
    cc : str, optional
        C compiler (default ``$CC`` or ``cc``).
    fmi_version : {2, 3}
    n : {2, 3}
        ``ArmExo.ArmExoPlant`` or ``ArmExo.ArmExoPlant3``.
    exported : dict, optional
        The exporter's result (default: :func:`export`).

    Returns
    -------
    Path of the ``.fmu`` (written atomically).

    Raises
    ------
    ExporterUnavailable, BuildError
    """
    if fmi_version not in FMI_HEADERS:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    exported = exported if exported is not None else export(n)
    out_dir = Path(out_dir) if out_dir is not None else BUILD_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    cc = cc or os.environ.get("CC", "cc")
    ident, name = identifier(n), fmu_name(fmi_version, n)
    t = table(exported)
    with tempfile.TemporaryDirectory(prefix="armexo-modelica-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for f in sorted(FRAMEWORK_DIR.glob("*.[ch]")):
            shutil.copy2(f, src / f.name)
        shutil.copy2(GLUE_DIR / "config.h", src / "config.h")
        shutil.copy2(GLUE_DIR / "model.c", src / "model.c")
        shutil.copy2(GLUE_DIR / "ArmExoModelica_all.c", src / f"{ident}_all.c")
        (src / "variables.h").write_text(header_text(exported, t, ident))
        (src / "generated.c").write_text(generated_c(exported))
        for h in FMI_HEADERS[fmi_version]:
            shutil.copy2(_fmi_header_dir() / h, src / h)
        if fmi_version == 3:
            (src / "buildDescription.xml").write_text(_BUILD_DESCRIPTION.format(ident=ident))
        description = Path(tmp) / "modelDescription.xml"
        description.write_text(model_description_text(exported, t, ident, fmi_version))
        pack_fmu(cc, [f for f in CFLAGS if f != "-Wextra"], fmi_version, src, ident,
                 description, out_dir / name,
                 f"# {exported['model']}\n\nExported from the Modelica package modelica/ArmExo "
                 f"by modelica {EXPORTER_VERSION} (fmus/modelica_build.py); see docs/plant.md.\n")
    return out_dir / name


def default_fmu_path(build_if_missing: bool = True, *, fmi_version: int = 2, n: int = 2) -> Path:
    """``fmus/build/ArmExoPlant_modelica.fmu`` (or ``_fmi3``, or ``ArmExoPlant3_modelica``),
    (re)built when missing or older than a source (Modelica files, exporter, framework).

    Raises
    ------
    ExporterUnavailable
        It must be built and no exporter interpreter exists.
    """
    path = BUILD_DIR / fmu_name(fmi_version, n)
    sources = (list(MODELICA_DIR.rglob("*.mo")) + list(EXPORT_DIR.glob("*.py")) + list(GLUE_DIR.iterdir())
               + list(FRAMEWORK_DIR.iterdir()) + [Path(__file__)])
    if path.exists() and (not build_if_missing
                          or max(f.stat().st_mtime for f in sources) <= path.stat().st_mtime):
        return path
    if not build_if_missing:
        raise FileNotFoundError(f"{path} not built: run `python -m fmus.build`")
    return build_fmu(fmi_version=fmi_version, n=n)


def build_all(out_dir=None, *, cc: str | None = None, log=print) -> list[Path]:
    """Every exported plant (FMI 2.0 and 3.0 for two joints, FMI 2.0 for three); a plant the
    exporter cannot export is reported in one line and skipped.

    Raises
    ------
    ExporterUnavailable
        No exporter interpreter (the caller falls back to the C plant).
    """
    python, built, unavailable = None, [], None
    for n in sorted(MODELS):
        try:
            if not (MODELICA_DIR / "package.mo").is_file():
                raise ExporterUnavailable(f"the Modelica source {MODELICA_DIR} is missing")
            cached = CACHE_DIR / f"{MODELS[n]}-{source_hash()[:16]}.json"
            if not cached.exists() and python is None:
                python = find_exporter()
            exported = export(n, python=python)
        except ExporterUnavailable as exc:
            unavailable = exc
            continue
        except BuildError as exc:
            log(f"note: the Modelica plant {MODELS[n]} was not exported: {exc}")
            continue
        for version in ((2, 3) if n == 2 else (2,)):
            built.append(build_fmu(out_dir, cc=cc, fmi_version=version, n=n, exported=exported))
    if unavailable is not None and not built:
        raise unavailable
    return built


if __name__ == "__main__":
    for p in build_all():
        print(p)
    sys.exit(0)
