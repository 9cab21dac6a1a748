"""A second plant FMU from another exporter: a linear n-DOF arm on a linear robot.

Built with pythonfmu (``orchestrator.plants.build_linear_arm_fmu``), it keeps the plant
contract (docs/spec/plant-contract.md) so the orchestrator drives it unchanged:

    (M_r + M_h) theta'' + B_h theta' + K_h theta = tau_m
    tau_h = M_h theta'' + B_h theta' + K_h theta

with a constant robot mass matrix ``M_r``, no friction and rigid coupling. The shipped
configuration is two joints (Table I); :func:`orchestrator.plants.build_linear_arm_fmu`
rewrites the configuration block below for n joints (the tractability study, n = 4..7). Each
communication step is integrated exactly for the input held over the step (zero-order-hold
discretisation with the matrix exponential), so the plant is analytic. The outputs are the
left limit at the end of the step with the held input (as the reference plant).

This file is the FMU's slave module: it imports only numpy, scipy and pythonfmu, and must
not use ``from __future__`` imports (pythonfmu's builder may prepend an import line).
"""
import numpy as np
from scipy.linalg import expm

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

# --- configuration (build_linear_arm_fmu rewrites this block for n joints) ---
# Table I (reference.md section 2) and the robot's mass matrix at the posture
# (reference.md section 3, q2 = 77.260 deg, Jm = 0.010 on the diagonal).
_M_H = ((0.187, 0.084), (0.079, 0.060))
_B_H = ((0.651, 0.239), (0.236, 0.407))
_K_H = ((7.967, 3.187), (1.663, 6.901))
_M_R = ((0.2090303562, 0.0524026781), (0.0524026781, 0.050825))
_POSTURE_DEG = (62.708, 77.260)
_N = 2
# --- end of configuration ---


class LinearArmPlant(Fmi2Slave):
    """Linear arm + linear robot, exact ZOH integration per communication step.

    Parameters
    ----------
    omit_outputs : tuple of str
        Contract outputs to leave out (``"tau_h"``, ``"omega"``...): used only to build a
        plant that breaks the contract for tests.
    """

    author = "arm-impedance-cosim"
    description = f"Linear {_N}-DOF arm on a linear robot (constant mass matrix, no friction)"

    def __init__(self, omit_outputs=(), **kwargs):
        super().__init__(**kwargs)
        self.M_h = np.array(_M_H, dtype=float)
        self.B_h = np.array(_B_H, dtype=float)
        self.K_h = np.array(_K_H, dtype=float)
        self.M_r = np.array(_M_R, dtype=float)
        self.posture_deg = np.array(_POSTURE_DEG, dtype=float)
        self.tau_m = np.zeros(_N)
        self.x = np.zeros(2 * _N)   # [theta, omega]
        self.tau_h = np.zeros(_N)
        self._cache = {}
        self._register_array("posture_deg", self.posture_deg, Fmi2Causality.parameter)
        for name in ("M_h", "B_h", "K_h"):
            self._register_matrix(f"arm.{name}", getattr(self, name))
        self._register_matrix("robot.M_r", self.M_r)
        self._register_array("tau_m", self.tau_m, Fmi2Causality.input)
        if "theta" not in omit_outputs:
            self._register_array("theta", self.x, Fmi2Causality.output)
        if "tau_h" not in omit_outputs:
            self._register_array("tau_h", self.tau_h, Fmi2Causality.output)
        if "omega" not in omit_outputs:
            self._register_array("omega", self.x, Fmi2Causality.output, offset=_N)

    # ------------------------------------------------------------------ registration
    def _register_array(self, name, array, causality, offset=0):
        for j in range(_N):
            k = offset + j
            self.register_variable(Real(
                f"{name}[{j + 1}]", causality=causality,
                variability=(Fmi2Variability.fixed if causality == Fmi2Causality.parameter
                             else Fmi2Variability.continuous),
                getter=lambda a=array, k=k: float(a[k]),
                setter=lambda v, a=array, k=k: a.__setitem__(k, v)), nested=False)

    def _register_matrix(self, name, matrix):
        for i in range(_N):
            for j in range(_N):
                self.register_variable(Real(
                    f"{name}[{i + 1},{j + 1}]", causality=Fmi2Causality.parameter,
                    variability=Fmi2Variability.fixed,
                    getter=lambda m=matrix, i=i, j=j: float(m[i, j]),
                    setter=lambda v, m=matrix, i=i, j=j: m.__setitem__((i, j), v)),
                    nested=False)

    # ------------------------------------------------------------------ dynamics
    def exit_initialization_mode(self):
        self._cache = {}
        self._update_outputs()

    def _output_map(self):
        """(Cy, Dy): tau_h = Cy [theta; omega] + Dy tau_m (from the parameters, cached)."""
        if "out" not in self._cache:
            n = _N
            m_inv = np.linalg.inv(self.M_r + self.M_h)
            acc_x = -m_inv @ np.hstack([self.K_h, self.B_h])   # accel = acc_x x + m_inv u
            cy = self.M_h @ acc_x + np.hstack([self.K_h, self.B_h])
            self._cache["out"] = (cy, self.M_h @ m_inv)
            assert cy.shape == (n, 2 * n)
        return self._cache["out"]

    def _discretised(self, h):
        """(Ad, Bd) of the ZOH discretisation for step h [s], cached per step."""
        key = round(h, 15)
        if key not in self._cache:
            n = _N
            m_inv = np.linalg.inv(self.M_r + self.M_h)
            aug = np.zeros((3 * n, 3 * n))
            aug[:n, n:2 * n] = np.eye(n)
            aug[n:2 * n, :n] = -m_inv @ self.K_h
            aug[n:2 * n, n:2 * n] = -m_inv @ self.B_h
            aug[n:2 * n, 2 * n:] = m_inv
            phi = expm(aug * h)
            self._cache[key] = (phi[:2 * n, :2 * n].copy(), phi[:2 * n, 2 * n:].copy())
        return self._cache[key]

    def _update_outputs(self):
        # tau_h = M_h accel + B_h omega + K_h theta, accel from the equation of motion
        cy, dy = self._output_map()
        self.tau_h[:] = cy @ self.x + dy @ self.tau_m

    def do_step(self, current_time, step_size):
        a_d, b_d = self._discretised(step_size)
        self.x[:] = a_d @ self.x + b_d @ self.tau_m
        self._update_outputs()
        return True
