/* ArmExoPlant: equations of the 2-DOF exoskeleton + linear human arm plant.
 *
 * See readme.md for the equations.  Angles are deviations from the posture q0;
 * absolute angles q = q0 + theta.  All effects of docs/spec/effects.md that live in
 * the plant are switched by their parameters (0, or scale 1, means off); the flags
 * and the state layout are fixed in model_initialize(), so the derivative only
 * branches on precomputed flags.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "framework.h"
#include "solver.h"

#if N_JOINTS != 2
#include "model_nlink.c"
#else  /* the two-link plant of record: its own code, unchanged (bit-identical results) */

#define DEG2RAD 0.017453292519943295
#define G_ACC 9.81

#define P(name) (r[vr_##name])
#define SINCOS_EXACT_EVERY 64   /* see model_beginStep() */

/* ---- parameter checks ------------------------------------------------------ */

static int refuse(ModelInstance *comp, int vr, const char *what) {
    logError(comp, "parameter %s = %.15g refused: %s", VR_NAME[vr], comp->s.r[vr], what);
    return 1;
}

#define REQUIRE(cond, vr, what) do { if (!(cond)) return refuse(comp, vr, what); } while (0)

/* det of [[A11 + 2 a3 c, A12 + a3 c], [A21 + a3 c, A22]] at cos q2 = c */
static double detAt(double A11, double A12, double A21, double A22, double a3, double c) {
    return (A11 + 2.0 * a3 * c) * A22 - (A12 + a3 * c) * (A21 + a3 * c);
}

int model_initialize(ModelInstance *comp) {
    Snapshot *s = &comp->s;
    const double *r = s->r;
    ModelData *d = &s->d;
    int j, n = 0;

    memset(d, 0, sizeof *d);

    /* --- validation (every refusal names the variable and its value) --- */
    REQUIRE(P(rk4_step) > 0.0, vr_rk4_step, "must be > 0");
    REQUIRE(P(robot_m1) > 0.0, vr_robot_m1, "mass must be > 0");
    REQUIRE(P(robot_m2) > 0.0, vr_robot_m2, "mass must be > 0");
    REQUIRE(P(robot_I1) >= 0.0, vr_robot_I1, "inertia must be >= 0");
    REQUIRE(P(robot_I2) >= 0.0, vr_robot_I2, "inertia must be >= 0");
    REQUIRE(P(robot_L1) > 0.0, vr_robot_L1, "length must be > 0");
    REQUIRE(P(robot_L2) > 0.0, vr_robot_L2, "length must be > 0");
    REQUIRE(P(robot_lc1) > 0.0, vr_robot_lc1, "length must be > 0");
    REQUIRE(P(robot_lc2) > 0.0, vr_robot_lc2, "length must be > 0");
    REQUIRE(P(robot_Jm_1) >= 0.0, vr_robot_Jm_1, "inertia must be >= 0");
    REQUIRE(P(robot_Jm_2) >= 0.0, vr_robot_Jm_2, "inertia must be >= 0");
    REQUIRE(P(inertia_mismatch_scale) > 0.0, vr_inertia_mismatch_scale, "scale must be > 0 (1: off)");
    REQUIRE(P(actuator_lag_time_constant_s) >= 0.0, vr_actuator_lag_time_constant_s, "time constant must be >= 0 (0: off)");
    REQUIRE(P(torque_sensor_lag_time_constant_s) >= 0.0, vr_torque_sensor_lag_time_constant_s, "time constant must be >= 0 (0: off)");
    REQUIRE(fabs(P(gravity_tilt_deg)) <= 90.0, vr_gravity_tilt_deg, "tilt must be within [-90, 90] deg");
    for (j = 0; j < N_JOINTS; j++) {
        REQUIRE(r[vr_transmission_compliance_k_t_1 + j] >= 0.0, vr_transmission_compliance_k_t_1 + j, "stiffness must be >= 0 (0: off)");
        REQUIRE(r[vr_transmission_compliance_c_t_1 + j] >= 0.0, vr_transmission_compliance_c_t_1 + j, "damping must be >= 0");
        REQUIRE(r[vr_interface_compliance_k_s_1 + j] >= 0.0, vr_interface_compliance_k_s_1 + j, "stiffness must be >= 0 (0: off)");
        REQUIRE(r[vr_interface_compliance_c_s_1 + j] >= 0.0, vr_interface_compliance_c_s_1 + j, "damping must be >= 0");
        REQUIRE(r[vr_friction_Fc_1 + j] >= 0.0, vr_friction_Fc_1 + j, "Coulomb friction must be >= 0");
        REQUIRE(r[vr_friction_Fs_1 + j] >= r[vr_friction_Fc_1 + j], vr_friction_Fs_1 + j, "static friction Fs must be >= Coulomb friction Fc");
        REQUIRE(r[vr_friction_sigma2_1 + j] >= 0.0, vr_friction_sigma2_1 + j, "viscous friction must be >= 0");
        if (r[vr_friction_Fs_1 + j] > 0.0) {
            REQUIRE(r[vr_friction_Fc_1 + j] > 0.0, vr_friction_Fc_1 + j, "Coulomb friction must be > 0 when Fs > 0 (LuGre)");
            REQUIRE(P(friction_sigma0) > 0.0, vr_friction_sigma0, "bristle stiffness must be > 0 when friction is on");
            REQUIRE(P(friction_sigma1) >= 0.0, vr_friction_sigma1, "bristle damping must be >= 0");
            REQUIRE(P(friction_ws) > 0.0, vr_friction_ws, "Stribeck velocity must be > 0 when friction is on");
        }
        if (r[vr_transmission_compliance_k_t_1 + j] > 0.0)
            REQUIRE(r[vr_robot_Jm_1 + j] > 0.0, vr_robot_Jm_1 + j, "motor inertia must be > 0 with transmission compliance");
    }
    {
        const int on1 = P(interface_compliance_k_s_1) > 0.0, on2 = P(interface_compliance_k_s_2) > 0.0;
        if (on1 != on2)
            return refuse(comp, on1 ? vr_interface_compliance_k_s_2 : vr_interface_compliance_k_s_1,
                          "interface compliance must be on for both joints or for neither");
    }

    /* --- derived constants --- */
    const double m1 = P(robot_m1), m2 = P(robot_m2), L1 = P(robot_L1);
    const double lc1 = P(robot_lc1), lc2 = P(robot_lc2), I1 = P(robot_I1), I2 = P(robot_I2);
    const double sc = P(inertia_mismatch_scale);
    d->a1 = sc * (I1 + m1 * lc1 * lc1 + I2 + m2 * (L1 * L1 + lc2 * lc2));
    d->a2 = sc * (I2 + m2 * lc2 * lc2);
    d->a3 = sc * (m2 * L1 * lc2);
    d->q0[0] = P(posture_deg_1) * DEG2RAD;
    d->q0[1] = P(posture_deg_2) * DEG2RAD;
    for (int i = 0; i < 2; i++)
        for (j = 0; j < 2; j++) {
            d->Mh[i][j] = r[vr_arm_M_h_1_1 + 2 * i + j];
            d->Bh[i][j] = r[vr_arm_B_h_1_1 + 2 * i + j];
            d->Kh[i][j] = r[vr_arm_K_h_1_1 + 2 * i + j];
        }
    const double beta = P(gravity_tilt_deg) * DEG2RAD;
    d->has_gravity = beta != 0.0;
    d->g1 = G_ACC * sin(beta) * (m1 * lc1 + m2 * L1);
    d->g2 = G_ACC * sin(beta) * m2 * lc2;
    d->sigma0 = P(friction_sigma0);
    d->sigma1 = P(friction_sigma1);
    d->inv_ws = P(friction_ws) > 0.0 ? 1.0 / P(friction_ws) : 0.0;
    for (j = 0; j < N_JOINTS; j++) {
        d->Jm[j] = r[vr_robot_Jm_1 + j];
        d->Fc[j] = r[vr_friction_Fc_1 + j];
        d->dF[j] = r[vr_friction_Fs_1 + j] - d->Fc[j];
        d->sigma2[j] = r[vr_friction_sigma2_1 + j];
        if (r[vr_friction_Fs_1 + j] > 0.0) {
            d->friction[j] = FRICTION_LUGRE;
            d->inv_Fc[j] = 1.0 / d->Fc[j];
            /* (Fs - Fc) exp(-a) < Fc 2^-55 for a > ln((Fs - Fc) / Fc) + 55 ln 2 */
            d->acut[j] = d->dF[j] > 0.0 ? log(d->dF[j] / d->Fc[j]) + 55.0 * 0.6931471805599453 : 0.0;
        }
        else if (d->sigma2[j] > 0.0) d->friction[j] = FRICTION_VISCOUS;
        else d->friction[j] = FRICTION_OFF;  /* level 0: no friction, no z dynamics */
        d->kt[j] = r[vr_transmission_compliance_k_t_1 + j];
        d->ct[j] = r[vr_transmission_compliance_c_t_1 + j];
        d->trans[j] = d->kt[j] > 0.0;
        d->Jlink[j] = d->trans[j] ? 0.0 : d->Jm[j];
        d->ks[j] = r[vr_interface_compliance_k_s_1 + j];
        d->cs[j] = r[vr_interface_compliance_c_s_1 + j];
    }
    d->has_iface = d->ks[0] > 0.0;
    d->has_act_lag = P(actuator_lag_time_constant_s) > 0.0;
    d->inv_Ta = d->has_act_lag ? 1.0 / P(actuator_lag_time_constant_s) : 0.0;
    d->has_sens_lag = P(torque_sensor_lag_time_constant_s) > 0.0;
    d->inv_Ts = d->has_sens_lag ? 1.0 / P(torque_sensor_lag_time_constant_s) : 0.0;

    /* --- mass matrices must be regular for every q2 (det is concave in cos q2) --- */
    {
        const double A11 = d->a1 + d->Jlink[0] + (d->has_iface ? 0.0 : d->Mh[0][0]);
        const double A12 = d->a2 + (d->has_iface ? 0.0 : d->Mh[0][1]);
        const double A21 = d->a2 + (d->has_iface ? 0.0 : d->Mh[1][0]);
        const double A22 = d->a2 + d->Jlink[1] + (d->has_iface ? 0.0 : d->Mh[1][1]);
        const double dm = detAt(A11, A12, A21, A22, d->a3, -1.0);
        const double dp = detAt(A11, A12, A21, A22, d->a3, 1.0);
        if (!(dm > 0.0 && dp > 0.0 && A22 > 0.0)) {
            logError(comp, "the mass matrix %s is singular or not positive definite "
                     "(det = %.6g at q2 = pi, %.6g at q2 = 0); check robot.* and arm.M_h",
                     d->has_iface ? "M_r(q)" : "M_r(q) + M_h", dm, dp);
            return 1;
        }
        if (d->has_iface) {
            const double det = d->Mh[0][0] * d->Mh[1][1] - d->Mh[0][1] * d->Mh[1][0];
            if (!(det > 0.0 && d->Mh[0][0] > 0.0)) {
                logError(comp, "arm.M_h is singular or not positive definite "
                         "(det = %.6g), required with interface compliance", det);
                return 1;
            }
            d->Mh_inv[0][0] = d->Mh[1][1] / det;
            d->Mh_inv[0][1] = -d->Mh[0][1] / det;
            d->Mh_inv[1][0] = -d->Mh[1][0] / det;
            d->Mh_inv[1][1] = d->Mh[0][0] / det;
        }
    }

    d->basic = !d->has_act_lag && !d->trans[0] && !d->trans[1] && !d->has_iface && !d->has_sens_lag;
    d->A11c = d->a1 + d->Jm[0] + d->Mh[0][0];
    d->A12c = d->a2 + d->Mh[0][1];
    d->A21c = d->a2 + d->Mh[1][0];
    d->A22c = d->a2 + d->Jm[1] + d->Mh[1][1];

    /* --- state layout (the fast path needs th, w, z at 0..5) --- */
    d->i_th = n; n += 2;
    d->i_w = n; n += 2;
    if (d->basic) {  /* fixed layout [th, w, z1, z2]: deriv_basic() reads z of joint j at 4 + j */
        for (j = 0; j < N_JOINTS; j++) d->i_z[j] = d->friction[j] == FRICTION_LUGRE ? 4 + j : NO_STATE;
        n = 6;       /* an unused z has zero derivative */
    } else {
        for (j = 0; j < N_JOINTS; j++) d->i_z[j] = d->friction[j] == FRICTION_LUGRE ? n++ : NO_STATE;
    }
    if (d->has_act_lag) { d->i_ta = n; n += 2; } else d->i_ta = NO_STATE;
    for (j = 0; j < N_JOINTS; j++) {
        if (d->trans[j]) { d->i_qm[j] = n++; d->i_wm[j] = n++; }
        else d->i_qm[j] = d->i_wm[j] = NO_STATE;
    }
    if (d->has_iface) { d->i_thh = n; n += 2; d->i_wh = n; n += 2; } else d->i_thh = d->i_wh = NO_STATE;
    if (d->has_sens_lag) { d->i_y = n; n += 2; } else d->i_y = NO_STATE;

    s->nx = n;
    s->h = P(rk4_step);
    memset(s->x, 0, sizeof s->x);   /* everything zero: posture, at rest, aligned */
    model_latchInputs(s);
    d->n_rotated = SINCOS_EXACT_EVERY;  /* first evaluation exact */
    model_beginStep(d, s->x);
    return 0;
}

/* ---- equations ------------------------------------------------------------- */

void model_latchInputs(Snapshot *s) {
    s->d.u[0] = s->r[vr_tau_m_1];
    s->d.u[1] = s->r[vr_tau_m_2];
}

/* sin/cos of q2 at the start of an RK4 step.  Between exact evaluations (every
 * SINCOS_EXACT_EVERY steps, and whenever q2 moved by 1e-4 rad or more) they are rotated
 * from the previous step's values by the Taylor series of sin e, cos e: dropped terms
 * < 5e-18, so the drift is rounding only (~1e-15 over the interval).  Saves a libm
 * sin + cos per step. */
static inline void model_beginStep(ModelData *d, const double *x) {
    const double q2 = d->q0[1] + x[d->i_th + 1], e = q2 - d->q2_ref;
    if (d->n_rotated < SINCOS_EXACT_EVERY && fabs(e) < 1e-4) {
        const double e2 = e * e;
        const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
        const double s2 = d->s2_ref * ce + d->c2_ref * se;
        d->c2_ref = d->c2_ref * ce - d->s2_ref * se;
        d->s2_ref = s2;
        d->n_rotated++;
    } else {
        d->s2_ref = sin(q2);
        d->c2_ref = cos(q2);
        d->n_rotated = 0;
    }
    d->q2_ref = q2;
}

typedef struct {
    double tau_h[2];    /* at the interface (before the sensor lag) */
    double tau_f[2];
    double tau_act[2];
} Aux;

/* LuGre friction torque of joint j at velocity v; *zdot receives z'.
 * g(v) = Fc + (Fs - Fc) exp(-(v/ws)^2); once (Fs - Fc) exp(-a) < Fc 2^-55 the sum
 * rounds to Fc exactly, so exp() is skipped for a > d->acut[j]. */
static inline double friction(const ModelData *d, int j, double v, double z, double *zdot) {
    switch (d->friction[j]) {
    case FRICTION_LUGRE: {
        const double rr = v * d->inv_ws, a = rr * rr;
        const double zg = a > d->acut[j] ? z * d->inv_Fc[j] : z / (d->Fc[j] + d->dF[j] * exp(-a));
        const double zd = v - d->sigma0 * fabs(v) * zg;
        *zdot = zd;
        return d->sigma0 * z + d->sigma1 * zd + d->sigma2[j] * v;
    }
    case FRICTION_VISCOUS:
        *zdot = 0.0;
        return d->sigma2[j] * v;
    default:
        *zdot = 0.0;
        return 0.0;
    }
}

/* sin/cos of q2 = q2_ref + e from those at the step start, with the Taylor series
 * of sin e and cos e: for |e| < 1e-4 the dropped terms (e^4/24, e^5/120) are below
 * 5e-18, i.e. the result is exact to rounding.  Saves a sincos per RK4 stage. */
__attribute__((always_inline)) static inline void sincos_q2(const ModelData *d, double th2, double *s2, double *c2) {
    const double q2 = th2 + d->q0[1], e = q2 - d->q2_ref;
    if (fabs(e) < 1e-4) {
        const double e2 = e * e;
        const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
        *s2 = d->s2_ref * ce + d->c2_ref * se;
        *c2 = d->c2_ref * ce - d->s2_ref * se;
    } else {
        *s2 = sin(q2);
        *c2 = cos(q2);
    }
}

/* Fast path (d->basic): x = [theta1, theta2, w1, w2, z1, z2]. */
__attribute__((always_inline)) static inline void deriv_basic(const ModelData *d, const double *x, double *dx) {
    const double th1 = x[0], th2 = x[1], w1 = x[2], w2 = x[3];
    double s2, c2, zd;
    sincos_q2(d, th2, &s2, &c2);
    double f1 = d->u[0], f2 = d->u[1];
    if (d->friction[0]) { f1 -= friction(d, 0, w1, x[4], &zd); dx[4] = zd; } else dx[4] = 0.0;
    if (d->friction[1]) { f2 -= friction(d, 1, w2, x[5], &zd); dx[5] = zd; } else dx[5] = 0.0;
    const double h3 = d->a3 * s2;
    f1 += h3 * (2.0 * w1 * w2 + w2 * w2);
    f2 -= h3 * w1 * w1;
    if (d->has_gravity) {
        const double q1 = d->q0[0] + th1, cq1 = cos(q1), sq1 = sin(q1);
        const double c12 = cq1 * c2 - sq1 * s2;
        f1 -= d->g1 * cq1 + d->g2 * c12;
        f2 -= d->g2 * c12;
    }
    f1 -= d->Bh[0][0] * w1 + d->Bh[0][1] * w2 + d->Kh[0][0] * th1 + d->Kh[0][1] * th2;
    f2 -= d->Bh[1][0] * w1 + d->Bh[1][1] * w2 + d->Kh[1][0] * th1 + d->Kh[1][1] * th2;
    const double ac = d->a3 * c2;
    const double A11 = d->A11c + 2.0 * ac, A12 = d->A12c + ac, A21 = d->A21c + ac, A22 = d->A22c;
    const double idet = 1.0 / (A11 * A22 - A12 * A21);
    dx[0] = w1;
    dx[1] = w2;
    dx[2] = (A22 * f1 - A12 * f2) * idet;
    dx[3] = (A11 * f2 - A21 * f1) * idet;
}

__attribute__((always_inline)) static inline void
evaluate(const ModelData *d, const double *x, double *dx, Aux *aux) {
    const double th1 = x[d->i_th], th2 = x[d->i_th + 1];
    const double w1 = x[d->i_w], w2 = x[d->i_w + 1];

    double s2, c2;
    sincos_q2(d, th2, &s2, &c2);

    /* actuator torque */
    double ta1, ta2;
    if (d->has_act_lag) {
        ta1 = x[d->i_ta]; ta2 = x[d->i_ta + 1];
        dx[d->i_ta] = (d->u[0] - ta1) * d->inv_Ta;
        dx[d->i_ta + 1] = (d->u[1] - ta2) * d->inv_Ta;
    } else {
        ta1 = d->u[0]; ta2 = d->u[1];
    }

    /* generalised force on the link side of each joint: tau_act - tau_f (rigid
     * transmission) or the transmission torque tau_t (compliant; friction on the motor) */
    double f1, f2, tf1, tf2, zd;
    if (!d->trans[0]) {
        tf1 = friction(d, 0, w1, d->i_z[0] >= 0 ? x[d->i_z[0]] : 0.0, &zd);
        if (d->i_z[0] >= 0) dx[d->i_z[0]] = zd;
        f1 = ta1 - tf1;
    } else {
        const double qm = x[d->i_qm[0]], wm = x[d->i_wm[0]];
        tf1 = friction(d, 0, wm, d->i_z[0] >= 0 ? x[d->i_z[0]] : 0.0, &zd);
        if (d->i_z[0] >= 0) dx[d->i_z[0]] = zd;
        f1 = d->kt[0] * (qm - th1) + d->ct[0] * (wm - w1);
        dx[d->i_qm[0]] = wm;
        dx[d->i_wm[0]] = (ta1 - tf1 - f1) / d->Jm[0];
    }
    if (!d->trans[1]) {
        tf2 = friction(d, 1, w2, d->i_z[1] >= 0 ? x[d->i_z[1]] : 0.0, &zd);
        if (d->i_z[1] >= 0) dx[d->i_z[1]] = zd;
        f2 = ta2 - tf2;
    } else {
        const double qm = x[d->i_qm[1]], wm = x[d->i_wm[1]];
        tf2 = friction(d, 1, wm, d->i_z[1] >= 0 ? x[d->i_z[1]] : 0.0, &zd);
        if (d->i_z[1] >= 0) dx[d->i_z[1]] = zd;
        f2 = d->kt[1] * (qm - th2) + d->ct[1] * (wm - w2);
        dx[d->i_qm[1]] = wm;
        dx[d->i_wm[1]] = (ta2 - tf2 - f2) / d->Jm[1];
    }

    /* Coriolis/centrifugal and gravity */
    const double h3 = d->a3 * s2;
    f1 -= -h3 * (2.0 * w1 * w2 + w2 * w2);
    f2 -= h3 * w1 * w1;
    if (d->has_gravity) {
        const double q1 = d->q0[0] + th1, cq1 = cos(q1), sq1 = sin(q1);
        const double c12 = cq1 * c2 - sq1 * s2;  /* cos(q1 + q2) */
        f1 -= d->g1 * cq1 + d->g2 * c12;
        f2 -= d->g2 * c12;
    }

    /* link (+ rigid arm) mass matrix */
    double A11 = d->a1 + 2.0 * d->a3 * c2 + d->Jlink[0];
    double A12 = d->a2 + d->a3 * c2, A21 = A12;
    double A22 = d->a2 + d->Jlink[1];
    double tau_h1, tau_h2;
    if (!d->has_iface) {
        /* rigid cuff: (M_link + M_h) a = f - B_h w - K_h theta; tau_h = M_h a + B_h w + K_h theta */
        const double p1 = d->Bh[0][0] * w1 + d->Bh[0][1] * w2 + d->Kh[0][0] * th1 + d->Kh[0][1] * th2;
        const double p2 = d->Bh[1][0] * w1 + d->Bh[1][1] * w2 + d->Kh[1][0] * th1 + d->Kh[1][1] * th2;
        A11 += d->Mh[0][0]; A12 += d->Mh[0][1]; A21 += d->Mh[1][0]; A22 += d->Mh[1][1];
        const double b1 = f1 - p1, b2 = f2 - p2;
        const double idet = 1.0 / (A11 * A22 - A12 * A21);
        const double acc1 = (A22 * b1 - A12 * b2) * idet;
        const double acc2 = (A11 * b2 - A21 * b1) * idet;
        dx[d->i_th] = w1; dx[d->i_th + 1] = w2;
        dx[d->i_w] = acc1; dx[d->i_w + 1] = acc2;
        tau_h1 = d->Mh[0][0] * acc1 + d->Mh[0][1] * acc2 + p1;
        tau_h2 = d->Mh[1][0] * acc1 + d->Mh[1][1] * acc2 + p2;
    } else {
        /* compliant cuff: spring-damper between robot and arm, the arm has its own states */
        const double thh1 = x[d->i_thh], thh2 = x[d->i_thh + 1];
        const double wh1 = x[d->i_wh], wh2 = x[d->i_wh + 1];
        tau_h1 = d->ks[0] * (th1 - thh1) + d->cs[0] * (w1 - wh1);
        tau_h2 = d->ks[1] * (th2 - thh2) + d->cs[1] * (w2 - wh2);
        const double b1 = f1 - tau_h1, b2 = f2 - tau_h2;
        const double idet = 1.0 / (A11 * A22 - A12 * A21);
        dx[d->i_th] = w1; dx[d->i_th + 1] = w2;
        dx[d->i_w] = (A22 * b1 - A12 * b2) * idet;
        dx[d->i_w + 1] = (A11 * b2 - A21 * b1) * idet;
        const double e1 = tau_h1 - (d->Bh[0][0] * wh1 + d->Bh[0][1] * wh2 + d->Kh[0][0] * thh1 + d->Kh[0][1] * thh2);
        const double e2 = tau_h2 - (d->Bh[1][0] * wh1 + d->Bh[1][1] * wh2 + d->Kh[1][0] * thh1 + d->Kh[1][1] * thh2);
        dx[d->i_thh] = wh1; dx[d->i_thh + 1] = wh2;
        dx[d->i_wh] = d->Mh_inv[0][0] * e1 + d->Mh_inv[0][1] * e2;
        dx[d->i_wh + 1] = d->Mh_inv[1][0] * e1 + d->Mh_inv[1][1] * e2;
    }

    if (d->has_sens_lag) {
        dx[d->i_y] = (tau_h1 - x[d->i_y]) * d->inv_Ts;
        dx[d->i_y + 1] = (tau_h2 - x[d->i_y + 1]) * d->inv_Ts;
    }

    if (aux) {
        aux->tau_h[0] = tau_h1; aux->tau_h[1] = tau_h2;
        aux->tau_f[0] = tf1; aux->tau_f[1] = tf2;
        aux->tau_act[0] = ta1; aux->tau_act[1] = ta2;
    }
}

__attribute__((always_inline)) static inline void deriv_general(const ModelData *d, const double *x, double *dx) {
    evaluate(d, x, dx, NULL);
}

RK4_DEFINE(rk4_basic, 6, 6, deriv_basic)
RK4_DEFINE(rk4_general, NX_MAX, s->nx, deriv_general)

int model_advance(Snapshot *s, long long n) {
    return s->d.basic ? rk4_basic(s, n) : rk4_general(s, n);
}

void model_calculateValues(Snapshot *s) {
    double dx[NX_MAX];
    Aux aux;
    double *r = s->r;
    const double *x = s->x;
    model_latchInputs(s);
    /* on a copy: reading outputs must not change the sin/cos bookkeeping of the solver */
    ModelData local = s->d;
    const ModelData *d = &local;
    model_beginStep(&local, x);
    evaluate(d, x, dx, &aux);
    for (int j = 0; j < N_JOINTS; j++) {
        const int enc_q = d->trans[j] ? d->i_qm[j] : d->i_th + j;
        const int enc_w = d->trans[j] ? d->i_wm[j] : d->i_w + j;
        r[vr_theta_1 + j] = x[enc_q];
        r[vr_omega_1 + j] = x[enc_w];
        r[vr_tau_h_1 + j] = d->has_sens_lag ? x[d->i_y + j] : aux.tau_h[j];
        r[vr_tau_f_1 + j] = aux.tau_f[j];
        r[vr_tau_act_1 + j] = aux.tau_act[j];
        r[vr_z_1 + j] = d->i_z[j] >= 0 ? x[d->i_z[j]] : 0.0;
        r[vr_theta_link_1 + j] = x[d->i_th + j];
        r[vr_theta_arm_1 + j] = d->has_iface ? x[d->i_thh + j] : x[d->i_th + j];
    }
}

const char *model_stateName(const ModelData *d, int i) {
    static const char *const names[] = {
        "theta_link[1]", "theta_link[2]", "omega_link[1]", "omega_link[2]", "z[1]", "z[2]",
        "tau_act[1]", "tau_act[2]", "theta_motor[1]", "omega_motor[1]", "theta_motor[2]", "omega_motor[2]",
        "theta_arm[1]", "theta_arm[2]", "omega_arm[1]", "omega_arm[2]", "tau_h_sensor[1]", "tau_h_sensor[2]"};
    if (i == d->i_th) return names[0];
    if (i == d->i_th + 1) return names[1];
    if (i == d->i_w) return names[2];
    if (i == d->i_w + 1) return names[3];
    for (int j = 0; j < N_JOINTS; j++) {
        if (i == d->i_z[j]) return names[4 + j];
        if (i == d->i_qm[j]) return names[8 + 2 * j];
        if (i == d->i_wm[j]) return names[9 + 2 * j];
    }
    if (d->i_ta >= 0 && (i == d->i_ta || i == d->i_ta + 1)) return names[6 + i - d->i_ta];
    if (d->i_thh >= 0 && (i == d->i_thh || i == d->i_thh + 1)) return names[12 + i - d->i_thh];
    if (d->i_wh >= 0 && (i == d->i_wh || i == d->i_wh + 1)) return names[14 + i - d->i_wh];
    if (d->i_y >= 0 && (i == d->i_y || i == d->i_y + 1)) return names[16 + i - d->i_y];
    return "?";
}

#endif  /* N_JOINTS == 2 */
