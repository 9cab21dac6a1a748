"""The IMBIC controller (reference.md section 7) against independent answers."""

import numpy as np
import pytest

from orchestrator import IMBIC, ControllerConfig, DivergenceError, SetupError

TS = 1e-3


def reference_imbic(cfg, active, theta, tau_h, tau_delta):
    """Second implementation: each joint as a linear state-space recursion in numpy,
    state s = [w_m, th_m, theta[n-1], theta[n-2], tau_m[n-1]], input v = [theta, u]."""
    n_samples, n = theta.shape
    out = np.zeros((n_samples, n))
    for j in range(n):
        m, b, k, mbar = cfg.M_rd[j], cfg.B_rd[j], cfg.K_rd[j], cfg.Mbar[j]
        kd, kp = 2 * cfg.wn[j], cfg.wn[j] ** 2
        tde = 1.0 if cfg.tde else 0.0
        # a_m = (u - b w - k (th_m - th_rd)) / m  ->  row over [s, theta, u] (+ const)
        a_row = np.array([-b / m, -k / m, 0, 0, 0, 0, 1 / m])
        a_const = k * cfg.theta_rd[j] / m
        w_hat = np.array([0, 0, -1 / TS, 0, 0, 1 / TS, 0])
        a_hat = np.array([0, 0, -2 / TS**2, 1 / TS**2, 0, 1 / TS**2, 0])
        tau_row = mbar * (a_row + kd * (np.array([1, 0, 0, 0, 0, 0, 0]) - w_hat)
                          + kp * np.array([0, 1, 0, 0, 0, -1, 0]))
        tau_row = tau_row + tde * (np.array([0, 0, 0, 0, 1, 0, 0]) - mbar * a_hat)
        s = np.array([0.0, cfg.theta_rd[j], 0, 0, 0])
        for i in range(n_samples):
            u = tau_delta[i, j] - tau_h[i, j] if active[j] else 0.0
            x = np.concatenate([s, [theta[i, j], u]])
            a_m = a_row @ x + a_const
            tau = tau_row @ x + mbar * a_const
            w_new = s[0] + TS * a_m
            s = np.array([w_new, s[1] + TS * w_new, theta[i, j], s[2], tau])
            out[i, j] = tau
    return out


@pytest.mark.parametrize("tuning", ["reference", "robust"])
@pytest.mark.parametrize("tde", [True, False])
@pytest.mark.parametrize("perturbed_dof", [1, 2, None])
def test_matches_second_implementation(tuning, tde, perturbed_dof):
    rng = np.random.default_rng(1)
    base = ControllerConfig.reference(tuning)
    cfg = ControllerConfig(**{**base.__dict__, "tde": tde, "theta_rd": (0.01, -0.02)})
    theta = np.cumsum(rng.normal(0, 1e-4, (400, 2)), axis=0)
    tau_h = rng.normal(0, 1, (400, 2))
    tau_delta = rng.normal(0, 3, (400, 2))
    ctl = IMBIC(cfg, perturbed_dof, torque_limit=np.inf)  # open loop: TDE integrates
    got = np.array([ctl.step(list(th) + list(th_), list(d))
                    for th, th_, d in zip(theta, tau_h, tau_delta)])
    active = [perturbed_dof is None or j == perturbed_dof - 1 for j in range(2)]
    want = reference_imbic(cfg, active, theta, tau_h, tau_delta)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_masking_holds_the_other_joint_model_at_rest():
    ctl = IMBIC(ControllerConfig.reference(), perturbed_dof=1, torque_limit=np.inf)
    rng = np.random.default_rng(2)
    for _ in range(200):
        ctl.step(list(rng.normal(0, 1e-3, 2)) + list(rng.normal(0, 1, 2)),
                 list(rng.normal(0, 5, 2)))
    th_m, w_m = ctl.internal_model
    assert th_m[1] == 0.0 and w_m[1] == 0.0
    assert th_m[0] != 0.0
    both = IMBIC(ControllerConfig.reference(), perturbed_dof=None)
    both.step([0, 0, 0.5, 0.5], [1.0, 1.0])
    both.step([0, 0, 0.5, 0.5], [1.0, 1.0])
    assert all(w != 0.0 for w in both.internal_model[1])


def _double_integrator(ctl, inertia, disturbance, n_samples):
    """Exact ZOH simulation of J theta'' = tau_m + d, joint 1 held (u_1 = 0)."""
    theta = omega = 0.0
    taus = []
    for _ in range(n_samples):
        tau = ctl.step([theta, 0.0, 0.0, 0.0], [0.0, 0.0])[0]
        acc = (tau + disturbance) / inertia
        theta, omega = theta + TS * omega + 0.5 * TS**2 * acc, omega + TS * acc
        taus.append(tau)
    return theta, taus[-1]


def test_tde_cancels_a_constant_disturbance_exactly():
    """Known answer: with TDE a held joint returns to theta_rd and tau_m -> -d; without
    TDE the PD law leaves the static error d / (Mbar wn^2)."""
    d, inertia = 0.5, 0.3
    cfg = ControllerConfig.reference()
    theta, tau = _double_integrator(IMBIC(cfg, perturbed_dof=2), inertia, d, 4000)
    assert abs(theta) < 1e-10 and tau == pytest.approx(-d, rel=1e-8)
    no_tde = ControllerConfig(**{**cfg.__dict__, "tde": False})
    theta, tau = _double_integrator(IMBIC(no_tde, perturbed_dof=2), inertia, d, 4000)
    assert theta == pytest.approx(d / (cfg.Mbar[0] * cfg.wn[0] ** 2), rel=1e-6)


def test_unstable_gains_raise_divergence():
    """Mbar far above twice the plant inertia makes TDE unstable: the command grows until
    the torque limit trips."""
    cfg = ControllerConfig(**{**ControllerConfig.reference().__dict__, "Mbar": (3.0, 3.0)})
    with pytest.raises(DivergenceError, match=r"tau_m\[1\]"):
        _double_integrator(IMBIC(cfg, perturbed_dof=2), 0.3, 0.5, 4000)


def test_reference_tunings():
    ref, rob = ControllerConfig.reference("reference"), ControllerConfig.reference("robust")
    assert ref.Mbar == (0.10, 0.03) and ref.wn == (150.0, 150.0)
    assert rob.Mbar == (0.018, 0.014) and rob.wn == (25.0, 25.0)
    assert ref.M_rd == (0.2, 0.05) and ref.B_rd == (1.0, 0.5) and ref.K_rd == (10.0, 5.0)


@pytest.mark.parametrize("change,match", [
    ({"Mbar": (0.0, 0.1)}, "Mbar"), ({"K_rd": (1.0,)}, "K_rd"), ({"Ts": 0.0}, "Ts")])
def test_bad_config(change, match):
    with pytest.raises(SetupError, match=match):
        ControllerConfig(**{**ControllerConfig.reference().__dict__, **change})
    with pytest.raises(SetupError, match="tuning"):
        ControllerConfig.reference("fast")
