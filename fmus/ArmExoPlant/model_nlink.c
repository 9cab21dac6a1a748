/* ArmExoPlant for n >= 3 planar links (included by model.c when N_JOINTS != 2).
 *
 * The same plant as the two-link model.c, written for any number of links: every
 * plant-side effect per joint, the same state layout rules and the same parameter checks.
 * Robot dynamics from the kinetic energy in absolute link angles phi_a = q_1 + ... + q_a:
 *
 *   T = 1/2 phi'^T D(phi) phi',   D_ab = d_ab cos(phi_a - phi_b)
 *   d_aa = I_a + m_a lc_a^2 + L_a^2 sum_{i>a} m_i,   d_ab = L_a (m_b lc_b + L_b sum_{i>b} m_i)  (a < b)
 *   Lagrange: Q_a = sum_b d_ab (cos(phi_a - phi_b) phi_b'' + sin(phi_a - phi_b) phi_b'^2)
 *   joint torques tau = S^T Q (phi = S q, S lower triangular of ones), so
 *   M_r(q) = S^T D S + diag(J),   c_r = S^T [sum_b d_ab sin(phi_a - phi_b) phi_b'^2]
 *   G = S^T [g sin(beta) (m_a lc_a + L_a sum_{i>a} m_i) cos phi_a]
 *
 * (Siciliano et al., Robotics, 2009, sec. 7.2 (Lagrange formulation); for n = 2 this is
 * reference.md's M_r, c_r and G term by term, for n = 3 reference-3dof.md's M_r and its
 * Christoffel-symbol c_r.)  inertia_mismatch.scale multiplies d (not Jm).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#define DEG2RAD 0.017453292519943295
#define G_ACC 9.81
#define NJ N_JOINTS
#define SINCOS_EXACT_EVERY 64   /* see model_beginStep() */

static int refuse(ModelInstance *comp, int vr, const char *what) {
    logError(comp, "parameter %s = %.15g refused: %s", VR_NAME[vr], comp->s.r[vr], what);
    return 1;
}

#define REQUIRE(cond, vr, what) do { if (!(cond)) return refuse(comp, vr, what); } while (0)

/* cos and sin of phi_b - phi_a = q_{a+1} + ... + q_b (a < b) from those of the joints */
__attribute__((always_inline)) static inline void
relative_angles(const double *s, const double *c, double C[NJ][NJ], double S[NJ][NJ]) {
    for (int a = 0; a < NJ - 1; a++) {
        C[a][a + 1] = c[a + 1];
        S[a][a + 1] = s[a + 1];
        for (int b = a + 2; b < NJ; b++) {
            C[a][b] = C[a][b - 1] * c[b] - S[a][b - 1] * s[b];
            S[a][b] = S[a][b - 1] * c[b] + C[a][b - 1] * s[b];
        }
    }
}

/* M_r(q) = S^T D S (without J): M_jk = sum_{a >= j} sum_{b >= k} D_ab */
__attribute__((always_inline)) static inline void
robot_mass(const ModelData *d, double C[NJ][NJ], double M[NJ][NJ]) {
    double R[NJ][NJ];
    for (int a = 0; a < NJ; a++) {
        double acc = 0.0;
        for (int b = NJ - 1; b >= 0; b--) {
            const double cab = a == b ? 1.0 : (a < b ? C[a][b] : C[b][a]);
            acc += d->d[a][b] * cab;
            R[a][b] = acc;
        }
    }
    for (int k = 0; k < NJ; k++) {
        double acc = 0.0;
        for (int j = NJ - 1; j >= 0; j--) {
            acc += R[j][k];
            M[j][k] = acc;
        }
    }
}

/* Solve A x = b in place (b <- x).  Three links: Cramer's rule with the adjugate (one
 * division).  Otherwise Gaussian elimination without pivoting: A is M_r + M_h, whose
 * leading minors model_initialize() checked over all angles. */
__attribute__((always_inline)) static inline void solve(double A[NJ][NJ], double *b) {
#if NJ == 3
    const double c00 = A[1][1] * A[2][2] - A[1][2] * A[2][1];
    const double c01 = A[1][2] * A[2][0] - A[1][0] * A[2][2];
    const double c02 = A[1][0] * A[2][1] - A[1][1] * A[2][0];
    const double idet = 1.0 / (A[0][0] * c00 + A[0][1] * c01 + A[0][2] * c02);
    const double c10 = A[0][2] * A[2][1] - A[0][1] * A[2][2];
    const double c11 = A[0][0] * A[2][2] - A[0][2] * A[2][0];
    const double c12 = A[0][1] * A[2][0] - A[0][0] * A[2][1];
    const double c20 = A[0][1] * A[1][2] - A[0][2] * A[1][1];
    const double c21 = A[0][2] * A[1][0] - A[0][0] * A[1][2];
    const double c22 = A[0][0] * A[1][1] - A[0][1] * A[1][0];
    const double b0 = b[0], b1 = b[1], b2 = b[2];
    b[0] = (c00 * b0 + c10 * b1 + c20 * b2) * idet;
    b[1] = (c01 * b0 + c11 * b1 + c21 * b2) * idet;
    b[2] = (c02 * b0 + c12 * b1 + c22 * b2) * idet;
    return;
#endif
    for (int k = 0; k < NJ; k++) {
        const double inv = 1.0 / A[k][k];
        for (int i = k + 1; i < NJ; i++) {
            const double f = A[i][k] * inv;
            for (int j = k + 1; j < NJ; j++) A[i][j] -= f * A[k][j];
            b[i] -= f * b[k];
        }
    }
    for (int k = NJ - 1; k >= 0; k--) {
        double acc = b[k];
        for (int j = k + 1; j < NJ; j++) acc -= A[k][j] * b[j];
        b[k] = acc / A[k][k];
    }
}

/* Smallest pivot of the elimination without pivoting (<= 0: a leading minor is not
 * positive). */
static double min_pivot(double A[NJ][NJ]) {
    double m = INFINITY;
    for (int k = 0; k < NJ; k++) {
        if (!(A[k][k] > 0.0)) return A[k][k];   /* also NaN */
        if (A[k][k] < m) m = A[k][k];
        for (int i = k + 1; i < NJ; i++) {
            const double f = A[i][k] / A[k][k];
            for (int j = k + 1; j < NJ; j++) A[i][j] -= f * A[k][j];
        }
    }
    return m;
}

/* the link (+ rigid arm) mass matrix at joint angles with sin/cos s, c */
static void link_mass(const ModelData *d, const double *s, const double *c, double A[NJ][NJ]) {
    double C[NJ][NJ], S[NJ][NJ];
    relative_angles(s, c, C, S);
    robot_mass(d, C, A);
    for (int j = 0; j < NJ; j++) {
        A[j][j] += d->Jlink[j];
        if (!d->has_iface)
            for (int k = 0; k < NJ; k++) A[j][k] += d->Mh[j][k];
    }
}

int model_initialize(ModelInstance *comp) {
    Snapshot *s = &comp->s;
    const double *r = s->r;
    ModelData *d = &s->d;
    int i, j, n = 0;

    memset(d, 0, sizeof *d);

    REQUIRE(r[vr_rk4_step] > 0.0, vr_rk4_step, "must be > 0");
    for (i = 0; i < NJ; i++) {  /* robot.m_i, L_i, lc_i, I_i are consecutive per link */
        const int base = vr_robot_m1 + 4 * i;
        REQUIRE(r[base] > 0.0, base, "mass must be > 0");
        REQUIRE(r[base + 1] > 0.0, base + 1, "length must be > 0");
        REQUIRE(r[base + 2] > 0.0, base + 2, "length must be > 0");
        REQUIRE(r[base + 3] >= 0.0, base + 3, "inertia must be >= 0");
        REQUIRE(r[vr_robot_Jm_1 + i] >= 0.0, vr_robot_Jm_1 + i, "inertia must be >= 0");
    }
    REQUIRE(r[vr_inertia_mismatch_scale] > 0.0, vr_inertia_mismatch_scale, "scale must be > 0 (1: off)");
    REQUIRE(r[vr_actuator_lag_time_constant_s] >= 0.0, vr_actuator_lag_time_constant_s, "time constant must be >= 0 (0: off)");
    REQUIRE(r[vr_torque_sensor_lag_time_constant_s] >= 0.0, vr_torque_sensor_lag_time_constant_s, "time constant must be >= 0 (0: off)");
    REQUIRE(fabs(r[vr_gravity_tilt_deg]) <= 90.0, vr_gravity_tilt_deg, "tilt must be within [-90, 90] deg");
    for (j = 0; j < NJ; j++) {
        REQUIRE(r[vr_transmission_compliance_k_t_1 + j] >= 0.0, vr_transmission_compliance_k_t_1 + j, "stiffness must be >= 0 (0: off)");
        REQUIRE(r[vr_transmission_compliance_c_t_1 + j] >= 0.0, vr_transmission_compliance_c_t_1 + j, "damping must be >= 0");
        REQUIRE(r[vr_interface_compliance_k_s_1 + j] >= 0.0, vr_interface_compliance_k_s_1 + j, "stiffness must be >= 0 (0: off)");
        REQUIRE(r[vr_interface_compliance_c_s_1 + j] >= 0.0, vr_interface_compliance_c_s_1 + j, "damping must be >= 0");
        REQUIRE(r[vr_friction_Fc_1 + j] >= 0.0, vr_friction_Fc_1 + j, "Coulomb friction must be >= 0");
        REQUIRE(r[vr_friction_Fs_1 + j] >= r[vr_friction_Fc_1 + j], vr_friction_Fs_1 + j, "static friction Fs must be >= Coulomb friction Fc");
        REQUIRE(r[vr_friction_sigma2_1 + j] >= 0.0, vr_friction_sigma2_1 + j, "viscous friction must be >= 0");
        if (r[vr_friction_Fs_1 + j] > 0.0) {
            REQUIRE(r[vr_friction_Fc_1 + j] > 0.0, vr_friction_Fc_1 + j, "Coulomb friction must be > 0 when Fs > 0 (LuGre)");
            REQUIRE(r[vr_friction_sigma0] > 0.0, vr_friction_sigma0, "bristle stiffness must be > 0 when friction is on");
            REQUIRE(r[vr_friction_sigma1] >= 0.0, vr_friction_sigma1, "bristle damping must be >= 0");
            REQUIRE(r[vr_friction_ws] > 0.0, vr_friction_ws, "Stribeck velocity must be > 0 when friction is on");
        }
        if (r[vr_transmission_compliance_k_t_1 + j] > 0.0)
            REQUIRE(r[vr_robot_Jm_1 + j] > 0.0, vr_robot_Jm_1 + j, "motor inertia must be > 0 with transmission compliance");
        if ((r[vr_interface_compliance_k_s_1 + j] > 0.0) != (r[vr_interface_compliance_k_s_1] > 0.0))
            return refuse(comp, vr_interface_compliance_k_s_1 + j,
                          "interface compliance must be on for every joint or for none");
    }

    /* --- derived constants --- */
    {
        const double sc = r[vr_inertia_mismatch_scale];
        double m[NJ], L[NJ], lc[NJ], I[NJ], tail[NJ + 1];  /* tail[a] = sum_{i >= a} m_i */
        for (i = 0; i < NJ; i++) {
            m[i] = r[vr_robot_m1 + 4 * i]; L[i] = r[vr_robot_m1 + 4 * i + 1];
            lc[i] = r[vr_robot_m1 + 4 * i + 2]; I[i] = r[vr_robot_m1 + 4 * i + 3];
        }
        tail[NJ] = 0.0;
        for (i = NJ - 1; i >= 0; i--) tail[i] = tail[i + 1] + m[i];
        for (int a = 0; a < NJ; a++) {
            d->d[a][a] = sc * (I[a] + m[a] * lc[a] * lc[a] + L[a] * L[a] * tail[a + 1]);
            for (int b = a + 1; b < NJ; b++)
                d->d[a][b] = d->d[b][a] = sc * L[a] * (m[b] * lc[b] + L[b] * tail[b + 1]);
        }
        const double beta = r[vr_gravity_tilt_deg] * DEG2RAD;
        d->has_gravity = beta != 0.0;
        for (int a = 0; a < NJ; a++)
            d->gq[a] = G_ACC * sin(beta) * (m[a] * lc[a] + L[a] * tail[a + 1]);
    }
    for (i = 0; i < NJ; i++) {
        d->q0[i] = r[vr_posture_deg_1 + i] * DEG2RAD;
        for (j = 0; j < NJ; j++) {
            d->Mh[i][j] = r[vr_arm_M_h_1_1 + NJ * i + j];
            d->Bh[i][j] = r[vr_arm_B_h_1_1 + NJ * i + j];
            d->Kh[i][j] = r[vr_arm_K_h_1_1 + NJ * i + j];
        }
    }
    d->sigma0 = r[vr_friction_sigma0];
    d->sigma1 = r[vr_friction_sigma1];
    d->inv_ws = r[vr_friction_ws] > 0.0 ? 1.0 / r[vr_friction_ws] : 0.0;
    for (j = 0; j < NJ; j++) {
        d->Jm[j] = r[vr_robot_Jm_1 + j];
        d->Fc[j] = r[vr_friction_Fc_1 + j];
        d->dF[j] = r[vr_friction_Fs_1 + j] - d->Fc[j];
        d->sigma2[j] = r[vr_friction_sigma2_1 + j];
        if (r[vr_friction_Fs_1 + j] > 0.0) {
            d->friction[j] = FRICTION_LUGRE;
            d->inv_Fc[j] = 1.0 / d->Fc[j];
            d->acut[j] = d->dF[j] > 0.0 ? log(d->dF[j] / d->Fc[j]) + 55.0 * 0.6931471805599453 : 0.0;
        }
        else if (d->sigma2[j] > 0.0) d->friction[j] = FRICTION_VISCOUS;
        else d->friction[j] = FRICTION_OFF;
        d->kt[j] = r[vr_transmission_compliance_k_t_1 + j];
        d->ct[j] = r[vr_transmission_compliance_c_t_1 + j];
        d->trans[j] = d->kt[j] > 0.0;
        d->Jlink[j] = d->trans[j] ? 0.0 : d->Jm[j];
        d->ks[j] = r[vr_interface_compliance_k_s_1 + j];
        d->cs[j] = r[vr_interface_compliance_c_s_1 + j];
    }
    d->has_iface = d->ks[0] > 0.0;
    d->has_act_lag = r[vr_actuator_lag_time_constant_s] > 0.0;
    d->inv_Ta = d->has_act_lag ? 1.0 / r[vr_actuator_lag_time_constant_s] : 0.0;
    d->has_sens_lag = r[vr_torque_sensor_lag_time_constant_s] > 0.0;
    d->inv_Ts = d->has_sens_lag ? 1.0 / r[vr_torque_sensor_lag_time_constant_s] : 0.0;

    /* --- the mass matrix must be regular at every posture: leading minors of
     * M_r(q) (+ M_h) on a grid of 8 values per relative joint angle (and at q0) --- */
    {
        int total = 1, g;
        for (j = 1; j < NJ; j++) total *= 8;
        for (g = -1; g < total; g++) {
            double sv[NJ], cv[NJ], A[NJ][NJ];
            int code = g;
            sv[0] = 0.0; cv[0] = 1.0;
            for (j = 1; j < NJ; j++) {
                const double q = g < 0 ? d->q0[j] : (code % 8) * (2.0 * 3.141592653589793 / 8.0);
                code /= 8;
                sv[j] = sin(q); cv[j] = cos(q);
            }
            link_mass(d, sv, cv, A);
            const double p = min_pivot(A);
            if (!(p > 0.0)) {
                logError(comp, "the mass matrix %s is singular or not positive definite at "
                         "some joint angles (pivot %.6g); check robot.* and arm.M_h",
                         d->has_iface ? "M_r(q)" : "M_r(q) + M_h", p);
                return 1;
            }
        }
    }
    if (d->has_iface) {  /* M_h^-1 by Gauss-Jordan (M_h checked regular) */
        double A[NJ][NJ], B[NJ][NJ];
        memcpy(A, d->Mh, sizeof A);
        double T[NJ][NJ];
        memcpy(T, d->Mh, sizeof T);
        const double p = min_pivot(T);
        if (!(p > 0.0)) {
            logError(comp, "arm.M_h is singular or not positive definite (pivot %.6g), "
                     "required with interface compliance", p);
            return 1;
        }
        for (i = 0; i < NJ; i++) for (j = 0; j < NJ; j++) B[i][j] = i == j;
        for (int k = 0; k < NJ; k++) {
            const double inv = 1.0 / A[k][k];
            for (j = 0; j < NJ; j++) { A[k][j] *= inv; B[k][j] *= inv; }
            for (i = 0; i < NJ; i++) {
                if (i == k) continue;
                const double f = A[i][k];
                for (j = 0; j < NJ; j++) { A[i][j] -= f * A[k][j]; B[i][j] -= f * B[k][j]; }
            }
        }
        memcpy(d->Mh_inv, B, sizeof B);
    }

    d->basic = !d->has_act_lag && !d->has_iface && !d->has_sens_lag;
    for (j = 0; j < NJ; j++) d->basic = d->basic && !d->trans[j];
    for (i = 0; i < NJ; i++)  /* constant part of M_r + M_h of the fast path */
        for (j = 0; j < NJ; j++) d->Ac[i][j] = d->Mh[i][j] + (i == j ? d->Jm[i] : 0.0);
    d->a1n = d->a2n = d->a3n = 0.0;
    for (i = 0; i < NJ; i++) d->a1n += d->d[i][i];
    for (i = 1; i < NJ; i++) d->a2n += d->d[i][i];
    d->a3n = d->d[NJ - 1][NJ - 1];

    /* --- state layout; the fast path has [th, w, z] at 0 .. 3n-1 --- */
    d->i_th = n; n += NJ;
    d->i_w = n; n += NJ;
    if (d->basic) {
        for (j = 0; j < NJ; j++) d->i_z[j] = 2 * NJ + j;  /* an unused z has zero derivative */
        n = 3 * NJ;
    } else {
        for (j = 0; j < NJ; j++) d->i_z[j] = d->friction[j] == FRICTION_LUGRE ? n++ : NO_STATE;
    }
    if (d->has_act_lag) { d->i_ta = n; n += NJ; } else d->i_ta = NO_STATE;
    for (j = 0; j < NJ; j++) {
        if (d->trans[j]) { d->i_qm[j] = n++; d->i_wm[j] = n++; }
        else d->i_qm[j] = d->i_wm[j] = NO_STATE;
    }
    if (d->has_iface) { d->i_thh = n; n += NJ; d->i_wh = n; n += NJ; } else d->i_thh = d->i_wh = NO_STATE;
    if (d->has_sens_lag) { d->i_y = n; n += NJ; } else d->i_y = NO_STATE;

    s->nx = n;
    s->h = r[vr_rk4_step];
    memset(s->x, 0, sizeof s->x);
    model_latchInputs(s);
    d->n_rotated = SINCOS_EXACT_EVERY;
    model_beginStep(d, s->x);
    return 0;
}

void model_latchInputs(Snapshot *s) {
    for (int j = 0; j < NJ; j++) s->d.u[j] = s->r[vr_tau_m_1 + j];
}

/* sin/cos of the relative joint angles q_2..q_n at the start of an RK4 step, rotated
 * from the previous step's by the Taylor series of sin e, cos e while |e| < 1e-4 (dropped
 * terms < 5e-18), exact every SINCOS_EXACT_EVERY steps: as the two-link model.c. */
static inline void model_beginStep(ModelData *d, const double *x) {
    int exact = d->n_rotated >= SINCOS_EXACT_EVERY;
    for (int j = 1; j < NJ && !exact; j++)
        exact = !(fabs(d->q0[j] + x[d->i_th + j] - d->q_ref[j]) < 1e-4);
    for (int j = 1; j < NJ; j++) {
        const double q = d->q0[j] + x[d->i_th + j];
        if (exact) {
            d->s_ref[j] = sin(q);
            d->c_ref[j] = cos(q);
        } else {
            const double e = q - d->q_ref[j], e2 = e * e;
            const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
            const double sn = d->s_ref[j] * ce + d->c_ref[j] * se;
            d->c_ref[j] = d->c_ref[j] * ce - d->s_ref[j] * se;
            d->s_ref[j] = sn;
        }
        d->q_ref[j] = q;
    }
    d->n_rotated = exact ? 0 : d->n_rotated + 1;
}

typedef struct {
    double tau_h[NJ];
    double tau_f[NJ];
    double tau_act[NJ];
} Aux;

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

/* f -= Coriolis/centrifugal and gravity torques (shared by evaluate() and the fast path):
 * c_j = sum_{a >= j} sum_b d_ab sin(phi_a - phi_b) phi_b'^2 */
__attribute__((always_inline)) static inline void
subtract_coriolis_gravity(const ModelData *d, double S[NJ][NJ], const double *w,
                          const double *th, double *f) {
    int a, b, j;
    {
        double pd2[NJ], acc = 0.0, qc[NJ];
        for (b = 0; b < NJ; b++) { acc += w[b]; pd2[b] = acc * acc; }
        for (a = 0; a < NJ; a++) {
            double q = 0.0;
            for (b = 0; b < a; b++) q += d->d[a][b] * S[b][a] * pd2[b];
            for (b = a + 1; b < NJ; b++) q -= d->d[a][b] * S[a][b] * pd2[b];
            qc[a] = q;
        }
        acc = 0.0;
        for (j = NJ - 1; j >= 0; j--) { acc += qc[j]; f[j] -= acc; }
    }
    if (d->has_gravity) {
        double phi = 0.0, acc = 0.0, qg[NJ];
        for (a = 0; a < NJ; a++) { phi += d->q0[a] + th[a]; qg[a] = d->gq[a] * cos(phi); }
        for (j = NJ - 1; j >= 0; j--) { acc += qg[j]; f[j] -= acc; }
    }
}

__attribute__((always_inline)) static inline void
evaluate(const ModelData *d, const double *x, double *dx, Aux *aux) {
    const double *th = x + d->i_th, *w = x + d->i_w;
    double sn[NJ], cs[NJ], C[NJ][NJ], S[NJ][NJ], A[NJ][NJ];
    double f[NJ], ta[NJ], tf[NJ], tau_h[NJ], zd;
    int a, b, j, k;

    sn[0] = 0.0; cs[0] = 1.0;
    for (j = 1; j < NJ; j++) {  /* Taylor rotation from the step start, as sincos_q2() */
        const double e = th[j] + d->q0[j] - d->q_ref[j];
        if (fabs(e) < 1e-4) {
            const double e2 = e * e;
            const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
            sn[j] = d->s_ref[j] * ce + d->c_ref[j] * se;
            cs[j] = d->c_ref[j] * ce - d->s_ref[j] * se;
        } else {
            sn[j] = sin(th[j] + d->q0[j]);
            cs[j] = cos(th[j] + d->q0[j]);
        }
    }
    relative_angles(sn, cs, C, S);

    for (j = 0; j < NJ; j++) {
        if (d->has_act_lag) {
            ta[j] = x[d->i_ta + j];
            dx[d->i_ta + j] = (d->u[j] - ta[j]) * d->inv_Ta;
        } else ta[j] = d->u[j];
        const int iz = d->i_z[j];
        if (!d->trans[j]) {
            tf[j] = friction(d, j, w[j], iz >= 0 ? x[iz] : 0.0, &zd);
            if (iz >= 0) dx[iz] = zd;
            f[j] = ta[j] - tf[j];
        } else {
            const double qm = x[d->i_qm[j]], wm = x[d->i_wm[j]];
            tf[j] = friction(d, j, wm, iz >= 0 ? x[iz] : 0.0, &zd);
            if (iz >= 0) dx[iz] = zd;
            f[j] = d->kt[j] * (qm - th[j]) + d->ct[j] * (wm - w[j]);
            dx[d->i_qm[j]] = wm;
            dx[d->i_wm[j]] = (ta[j] - tf[j] - f[j]) / d->Jm[j];
        }
    }

    subtract_coriolis_gravity(d, S, w, th, f);

    robot_mass(d, C, A);
    for (j = 0; j < NJ; j++) A[j][j] += d->Jlink[j];
    if (!d->has_iface) {
        double p[NJ], acc[NJ];
        for (j = 0; j < NJ; j++) {
            double pj = 0.0;
            for (k = 0; k < NJ; k++) { pj += d->Bh[j][k] * w[k] + d->Kh[j][k] * th[k]; A[j][k] += d->Mh[j][k]; }
            p[j] = pj;
            acc[j] = f[j] - pj;
        }
        solve(A, acc);
        for (j = 0; j < NJ; j++) {
            double t = p[j];
            for (k = 0; k < NJ; k++) t += d->Mh[j][k] * acc[k];
            tau_h[j] = t;
            dx[d->i_th + j] = w[j];
            dx[d->i_w + j] = acc[j];
        }
    } else {
        const double *thh = x + d->i_thh, *wh = x + d->i_wh;
        double acc[NJ], e[NJ];
        for (j = 0; j < NJ; j++) {
            tau_h[j] = d->ks[j] * (th[j] - thh[j]) + d->cs[j] * (w[j] - wh[j]);
            acc[j] = f[j] - tau_h[j];
            double pj = 0.0;
            for (k = 0; k < NJ; k++) pj += d->Bh[j][k] * wh[k] + d->Kh[j][k] * thh[k];
            e[j] = tau_h[j] - pj;
        }
        solve(A, acc);
        for (j = 0; j < NJ; j++) {
            double ah = 0.0;
            for (k = 0; k < NJ; k++) ah += d->Mh_inv[j][k] * e[k];
            dx[d->i_th + j] = w[j];
            dx[d->i_w + j] = acc[j];
            dx[d->i_thh + j] = wh[j];
            dx[d->i_wh + j] = ah;
        }
    }
    if (d->has_sens_lag)
        for (j = 0; j < NJ; j++) dx[d->i_y + j] = (tau_h[j] - x[d->i_y + j]) * d->inv_Ts;
    if (aux)
        for (j = 0; j < NJ; j++) { aux->tau_h[j] = tau_h[j]; aux->tau_f[j] = tf[j]; aux->tau_act[j] = ta[j]; }
}

__attribute__((always_inline)) static inline void deriv_general(const ModelData *d, const double *x, double *dx) {
    evaluate(d, x, dx, NULL);
}

/* sin/cos of joint j (1-based j+1) at th + q0, rotated from the step start's by the
 * Taylor series (as sincos_q2 of the two-link model.c). */
__attribute__((always_inline)) static inline void rotated(const ModelData *d, int j, double th, double *s, double *c) {
    const double e = th + d->q0[j] - d->q_ref[j];
    if (fabs(e) < 1e-4) {
        const double e2 = e * e;
        const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
        *s = d->s_ref[j] * ce + d->c_ref[j] * se;
        *c = d->c_ref[j] * ce - d->s_ref[j] * se;
    } else {
        *s = sin(th + d->q0[j]);
        *c = cos(th + d->q0[j]);
    }
}

#if NJ == 3
/* Fast path (d->basic), three links written out: x = [theta, w, z]; M_r(q) in
 * reference-3dof.md's form (a1 = d11 + d22 + d33, a2 = d22 + d33, a3 = d33, b12 = d12,
 * b13 = d13, b23 = d23), Coriolis from evaluate()'s sums with S01 = sin q2, S02 =
 * sin(q2 + q3), S12 = sin q3.  Same equations as evaluate() without the effects. */
__attribute__((always_inline)) static inline void deriv_basic(const ModelData *d, const double *x, double *dx) {
    const double th1 = x[0], th2 = x[1], th3 = x[2], w1 = x[3], w2 = x[4], w3 = x[5];
    double s2, c2, s3, c3, zd, f[3], A[3][3];
    rotated(d, 1, th2, &s2, &c2);
    rotated(d, 2, th3, &s3, &c3);
    const double c23 = c2 * c3 - s2 * s3, s23 = s2 * c3 + c2 * s3;
    for (int j = 0; j < 3; j++) {
        f[j] = d->u[j] - (d->Bh[j][0] * w1 + d->Bh[j][1] * w2 + d->Bh[j][2] * w3
                          + d->Kh[j][0] * th1 + d->Kh[j][1] * th2 + d->Kh[j][2] * th3);
        if (d->friction[j]) { f[j] -= friction(d, j, x[3 + j], x[6 + j], &zd); dx[6 + j] = zd; }
        else dx[6 + j] = 0.0;
    }
    {
        const double b12 = d->d[0][1], b13 = d->d[0][2], b23 = d->d[1][2];
        const double p1 = w1, p2 = w1 + w2, p3 = p2 + w3;
        const double P1 = p1 * p1, P2 = p2 * p2, P3 = p3 * p3;
        const double q3 = b13 * s23 * P1 + b23 * s3 * P2;
        const double q2 = b12 * s2 * P1 - b23 * s3 * P3 + q3;
        const double q1 = -b12 * s2 * P2 - b13 * s23 * P3 + q2;
        f[0] -= q1; f[1] -= q2; f[2] -= q3;
        const double h12 = b12 * c2, h13 = b13 * c23, h23 = b23 * c3;
        const double M13 = d->a3n + h13 + h23, M23 = d->a3n + h23;
        const double M12 = d->a2n + h12 + h13 + 2.0 * h23, M22 = d->a2n + 2.0 * h23;
        const double M11 = d->a1n + 2.0 * (h12 + h13 + h23);
        A[0][0] = M11 + d->Ac[0][0]; A[0][1] = M12 + d->Ac[0][1]; A[0][2] = M13 + d->Ac[0][2];
        A[1][0] = M12 + d->Ac[1][0]; A[1][1] = M22 + d->Ac[1][1]; A[1][2] = M23 + d->Ac[1][2];
        A[2][0] = M13 + d->Ac[2][0]; A[2][1] = M23 + d->Ac[2][1]; A[2][2] = d->a3n + d->Ac[2][2];
    }
    if (d->has_gravity) {
        double phi = 0.0, acc = 0.0, qg[NJ];
        for (int a = 0; a < NJ; a++) { phi += d->q0[a] + x[a]; qg[a] = d->gq[a] * cos(phi); }
        for (int j = NJ - 1; j >= 0; j--) { acc += qg[j]; f[j] -= acc; }
    }
    solve(A, f);
    dx[0] = w1; dx[1] = w2; dx[2] = w3;
    dx[3] = f[0]; dx[4] = f[1]; dx[5] = f[2];
}
#else
/* Fast path (d->basic): x = [theta, w, z], rigid transmission and cuff, no lags; the same
 * equations as evaluate() without the effects and without tau_h. */
__attribute__((always_inline)) static inline void deriv_basic(const ModelData *d, const double *x, double *dx) {
    const double *th = x, *w = x + NJ, *z = x + 2 * NJ;
    double sn[NJ], cs[NJ], C[NJ][NJ], S[NJ][NJ], A[NJ][NJ], f[NJ], zd;
    int a, b, j, k;
    sn[0] = 0.0; cs[0] = 1.0;
    for (j = 1; j < NJ; j++) {
        const double e = th[j] + d->q0[j] - d->q_ref[j];
        if (fabs(e) < 1e-4) {
            const double e2 = e * e;
            const double se = e - e * e2 * (1.0 / 6.0), ce = 1.0 - 0.5 * e2;
            sn[j] = d->s_ref[j] * ce + d->c_ref[j] * se;
            cs[j] = d->c_ref[j] * ce - d->s_ref[j] * se;
        } else {
            sn[j] = sin(th[j] + d->q0[j]);
            cs[j] = cos(th[j] + d->q0[j]);
        }
    }
    relative_angles(sn, cs, C, S);
    for (j = 0; j < NJ; j++) {
        f[j] = d->u[j];
        if (d->friction[j]) { f[j] -= friction(d, j, w[j], z[j], &zd); dx[2 * NJ + j] = zd; }
        else dx[2 * NJ + j] = 0.0;
        for (k = 0; k < NJ; k++) f[j] -= d->Bh[j][k] * w[k] + d->Kh[j][k] * th[k];
    }
    subtract_coriolis_gravity(d, S, w, th, f);
    robot_mass(d, C, A);
    for (j = 0; j < NJ; j++)
        for (k = 0; k < NJ; k++) A[j][k] += d->Ac[j][k];
    solve(A, f);
    for (j = 0; j < NJ; j++) { dx[j] = w[j]; dx[NJ + j] = f[j]; }
}

#endif

RK4_DEFINE(rk4_basic, 3 * NJ, 3 * NJ, deriv_basic)
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
    ModelData local = s->d;   /* reading outputs must not change the solver's sin/cos */
    const ModelData *d = &local;
    model_beginStep(&local, x);
    evaluate(d, x, dx, &aux);
    for (int j = 0; j < NJ; j++) {
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
    static char name[40];
    const char *what = "?";
    int j = 0;
    if (i >= d->i_th && i < d->i_th + NJ) { what = "theta_link"; j = i - d->i_th; }
    else if (i >= d->i_w && i < d->i_w + NJ) { what = "omega_link"; j = i - d->i_w; }
    else if (d->i_ta >= 0 && i >= d->i_ta && i < d->i_ta + NJ) { what = "tau_act"; j = i - d->i_ta; }
    else if (d->i_thh >= 0 && i >= d->i_thh && i < d->i_thh + NJ) { what = "theta_arm"; j = i - d->i_thh; }
    else if (d->i_wh >= 0 && i >= d->i_wh && i < d->i_wh + NJ) { what = "omega_arm"; j = i - d->i_wh; }
    else if (d->i_y >= 0 && i >= d->i_y && i < d->i_y + NJ) { what = "tau_h_sensor"; j = i - d->i_y; }
    else
        for (int k = 0; k < NJ; k++) {
            if (i == d->i_z[k]) { what = "z"; j = k; }
            if (i == d->i_qm[k]) { what = "theta_motor"; j = k; }
            if (i == d->i_wm[k]) { what = "omega_motor"; j = k; }
        }
    snprintf(name, sizeof name, "%s[%d]", what, j + 1);
    return name;
}
