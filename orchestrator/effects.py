"""The catalogue of unmodelled effects (docs/spec/effects.md), parsed and split by side.

Plant-side effects become FMU parameters (named ``<effect>.<param>[j]``); the sampler- and
actuator-side ones (``delay``, ``sensor_noise``, ``quantization``) live in the master.
Effects are applied in the simulation and recorded under ``meta["simulation"]``, never in
the declared set-up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .errors import EffectError

JOINT, SCALAR, INTEGER = "per joint", "scalar", "integer"

#: effect -> parameter -> kind. Plant-side effects are those mapped to FMU parameters.
CATALOGUE = {
    "friction": {"Fc": JOINT, "Fs": JOINT, "sigma2": JOINT,
                 "sigma0": SCALAR, "sigma1": SCALAR, "ws": SCALAR},
    "actuator_lag": {"time_constant_s": SCALAR},
    "transmission_compliance": {"k_t": JOINT, "c_t": JOINT},
    "interface_compliance": {"k_s": JOINT, "c_s": JOINT},
    "gravity": {"tilt_deg": SCALAR},
    "inertia_mismatch": {"scale": SCALAR},
    "torque_sensor_lag": {"time_constant_s": SCALAR},
    "delay": {"samples": INTEGER},
    "sensor_noise": {"theta_noise_std_rad": JOINT, "tau_noise_std_nm": JOINT},
    "quantization": {"encoder_resolution_deg": SCALAR, "torque_resolution_nm": SCALAR},
}
MASTER_SIDE = ("delay", "sensor_noise", "quantization")
#: parameters that may be negative (everything else must be >= 0)
SIGNED = {("gravity", "tilt_deg")}
#: parameters that must be > 0
POSITIVE = {("inertia_mismatch", "scale"), ("delay", "samples")}
#: upper limits, refused up front (a delay line of 1e8 samples would exhaust memory)
MAXIMUM = {("delay", "samples"): 100_000}


@dataclass
class Effects:
    """Effects to simulate, normalised (per-joint lists of length n).

    Attributes
    ----------
    normalized : dict
        ``{effect: {param: value or list}}`` as given, scalars broadcast for per-joint
        parameters; goes into ``meta["simulation"]["effects"]``.
    plant_parameters : dict
        FMU parameter name -> value for the plant-side effects.
    delay_samples : int
        Extra actuation delay d (0: none): tau_m[n] acts from (n + d) Ts.
    theta_noise_std, tau_noise_std : list of float [rad], [N m]
        Sensor noise standard deviation per joint (0: none).
    encoder_resolution_deg, torque_resolution_nm : float or None
        Resolution of the truth sensors (None: the declared sensors').
    """

    normalized: dict = field(default_factory=dict)
    plant_parameters: dict = field(default_factory=dict)
    delay_samples: int = 0
    theta_noise_std: list = field(default_factory=list)
    tau_noise_std: list = field(default_factory=list)
    encoder_resolution_deg: float | None = None
    torque_resolution_nm: float | None = None


def parse_effects(effects: dict | None, n_dof: int) -> Effects:
    """Check and normalise an effects dict (docs/spec/effects.md names and units).

    Parameters
    ----------
    effects : dict or None
        ``{name: {param: value}}``; scalars are broadcast to the joints for per-joint
        parameters. Missing parameters leave that part of the effect off (friction: the
        plant keeps the declared value).
    n_dof : int
        Number of joints n.

    Raises
    ------
    EffectError
        Unknown effect or parameter, wrong length, non-finite, negative or non-integer value.
    """
    out = Effects(theta_noise_std=[0.0] * n_dof, tau_noise_std=[0.0] * n_dof)
    if effects is None:
        return out
    if not isinstance(effects, dict):
        raise EffectError(f"effects must be a dict {{name: {{param: value}}}}, got "
                          f"{type(effects).__name__}")
    for name, params in effects.items():
        if name not in CATALOGUE:
            raise EffectError(f"unknown effect {name!r}; the catalogue has: "
                              f"{', '.join(CATALOGUE)}")
        if not isinstance(params, dict):
            raise EffectError(f"effect {name!r}: parameters must be a dict, got {params!r}")
        clean = {}
        for param, value in params.items():
            kind = CATALOGUE[name].get(param)
            if kind is None:
                raise EffectError(f"effect {name!r} has no parameter {param!r}; expected "
                                  f"{', '.join(CATALOGUE[name])}")
            clean[param] = _check_value(name, param, kind, value, n_dof)
        out.normalized[name] = clean
        _apply(out, name, clean, n_dof)
    return out


def _check_value(name, param, kind, value, n_dof):
    where = f"effect {name!r} parameter {param!r}"
    if kind == INTEGER:
        if isinstance(value, bool) or not isinstance(value, int) or float(value) != value:
            raise EffectError(f"{where} must be an integer, got {value!r}")
        values = [int(value)]
    elif kind == JOINT:
        values = list(value) if isinstance(value, (list, tuple)) else [value] * n_dof
        if len(values) != n_dof:
            raise EffectError(f"{where} needs {n_dof} values (one per joint) or a scalar, "
                              f"got {len(values)}")
    else:
        values = [value]
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise EffectError(f"{where} must be a finite number, got {v!r}")
        if (name, param) in POSITIVE and not v > 0:
            raise EffectError(f"{where} must be > 0, got {v!r}")
        if (name, param) not in SIGNED and v < 0:
            raise EffectError(f"{where} must be >= 0, got {v!r}")
        if (name, param) in MAXIMUM and v > MAXIMUM[name, param]:
            raise EffectError(f"{where} must be <= {MAXIMUM[name, param]}, got {v!r}")
    if kind == JOINT:
        return [float(v) for v in values]
    return values[0] if kind == INTEGER else float(values[0])


def _apply(out: Effects, name: str, params: dict, n_dof: int) -> None:
    if name == "delay":
        out.delay_samples = params.get("samples", 0)
    elif name == "sensor_noise":
        out.theta_noise_std = params.get("theta_noise_std_rad", [0.0] * n_dof)
        out.tau_noise_std = params.get("tau_noise_std_nm", [0.0] * n_dof)
    elif name == "quantization":
        out.encoder_resolution_deg = params.get("encoder_resolution_deg")
        out.torque_resolution_nm = params.get("torque_resolution_nm")
    else:
        out.plant_parameters.update(plant_parameter_names(name, params))


def plant_parameter_names(name: str, params: dict) -> dict:
    """FMU parameter names and values of one plant-side effect: ``k_t: [a, b]`` ->
    ``transmission_compliance.k_t[1]: a, ...[2]: b``."""
    out = {}
    for param, value in params.items():
        if isinstance(value, list):
            for j, v in enumerate(value, 1):
                out[f"{name}.{param}[{j}]"] = v
        else:
            out[f"{name}.{param}"] = value
    return out
