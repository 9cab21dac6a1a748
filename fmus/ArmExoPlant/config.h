/* ArmExoPlant: model configuration (identifier, GUID, value references, model data). */
#ifndef CONFIG_H
#define CONFIG_H

/* N_JOINTS: number of planar links, 2 unless the build defines it (the n-link plants
 * compile {MODEL}N_all.c, which defines it).  MODEL_IDENTIFIER_STRING,
 * INSTANTIATION_TOKEN (the GUID), N_VR, the enum vr_..., VR_NAME, VR_CAUSALITY and
 * VR_START: generated from fmus/variables.py for that n. */
#ifndef N_JOINTS
#define N_JOINTS 2
#endif
#if N_JOINTS == 2
#include "variables.h"
#elif N_JOINTS == 3
#include "variables.n3.h"
#else
#error "no variable table for this N_JOINTS (fmus/variables.py DEFAULTS)"
#endif

#if N_JOINTS == 2
/* theta, w (4) + z (2) + tau_act (2) + q_mot, w_mot (4) + theta_h, w_h (4) + y (2) */
#define NX_MAX 18
#define NO_STATE (-1)

/* Friction mode of one joint. */
enum { FRICTION_OFF = 0, FRICTION_VISCOUS = 1, FRICTION_LUGRE = 2 };

/* Derived constants, effect flags and the state layout, fixed at initialisation. */
typedef struct {
    /* inputs latched at the start of a communication step */
    double u[N_JOINTS];

    /* robot (a1..a3 scaled by inertia_mismatch.scale) */
    double a1, a2, a3, Jm[N_JOINTS];
    double q0[N_JOINTS];            /* posture [rad] */
    double Jlink[N_JOINTS];         /* Jm on the link diagonal (0 for a compliant transmission) */

    /* human arm, as printed */
    double Mh[2][2], Bh[2][2], Kh[2][2];
    double Mh_inv[2][2];            /* for interface compliance */

    /* gravity */
    int has_gravity;
    double g1, g2;                  /* g sin(beta) (m1 lc1 + m2 L1), g sin(beta) m2 lc2 */

    /* friction per joint */
    int friction[N_JOINTS];
    double Fc[N_JOINTS], dF[N_JOINTS], sigma2[N_JOINTS];
    double inv_Fc[N_JOINTS], acut[N_JOINTS]; /* 1/Fc; skip exp() above acut */
    double sigma0, sigma1, inv_ws;

    /* effects */
    int has_act_lag;   double inv_Ta;
    int trans[N_JOINTS]; double kt[N_JOINTS], ct[N_JOINTS];
    int has_iface;     double ks[N_JOINTS], cs[N_JOINTS];
    int has_sens_lag;  double inv_Ts;

    /* state layout: index into x, or NO_STATE */
    int i_th, i_w;                  /* link angle, link velocity (always) */
    int i_z[N_JOINTS];              /* LuGre bristle state */
    int i_ta;                       /* tau_act (actuator lag) */
    int i_qm[N_JOINTS], i_wm[N_JOINTS]; /* motor side (transmission compliance) */
    int i_thh, i_wh;                /* arm states (interface compliance) */
    int i_y;                        /* torque sensor state (sensor lag) */

    /* fast path: rigid transmission and cuff, no lags (state th, w, z: 6) */
    int basic;
    double A11c, A12c, A21c, A22c;  /* constant parts of M_r + M_h (with Jm) */

    /* sin/cos of q2 at the start of the current RK4 step */
    double q2_ref, s2_ref, c2_ref;
    int n_rotated;                  /* steps since the last exact sin/cos */
} ModelData;

#else  /* N_JOINTS >= 3: the n-link plant (model_nlink.c) */

/* theta, w (2n) + z (n) + tau_act (n) + q_mot, w_mot (2n) + theta_h, w_h (2n) + y (n) */
#define NX_MAX (9 * N_JOINTS)
#define NO_STATE (-1)

enum { FRICTION_OFF = 0, FRICTION_VISCOUS = 1, FRICTION_LUGRE = 2 };

typedef struct {
    double u[N_JOINTS];

    /* robot: kinetic energy (1/2) phi'^T D(phi) phi' in absolute link angles phi,
     * D_ab = d[a][b] cos(phi_a - phi_b) (d scaled by inertia_mismatch.scale) */
    double d[N_JOINTS][N_JOINTS], Jm[N_JOINTS], Jlink[N_JOINTS];
    double q0[N_JOINTS];

    double Mh[N_JOINTS][N_JOINTS], Bh[N_JOINTS][N_JOINTS], Kh[N_JOINTS][N_JOINTS];
    double Mh_inv[N_JOINTS][N_JOINTS];

    int has_gravity;
    double gq[N_JOINTS];            /* g sin(beta) (m_a lc_a + L_a sum_{i>a} m_i) */

    int friction[N_JOINTS];
    double Fc[N_JOINTS], dF[N_JOINTS], sigma2[N_JOINTS];
    double inv_Fc[N_JOINTS], acut[N_JOINTS];
    double sigma0, sigma1, inv_ws;

    int has_act_lag;   double inv_Ta;
    int trans[N_JOINTS]; double kt[N_JOINTS], ct[N_JOINTS];
    int has_iface;     double ks[N_JOINTS], cs[N_JOINTS];
    int has_sens_lag;  double inv_Ts;

    int i_th, i_w, i_z[N_JOINTS], i_ta, i_qm[N_JOINTS], i_wm[N_JOINTS], i_thh, i_wh, i_y;
    int basic;                      /* rigid transmission and cuff, no lags */
    double Ac[N_JOINTS][N_JOINTS];  /* M_h + diag(Jm): constant part of the fast path's matrix */
    double a1n, a2n, a3n;           /* sum of d_aa from a = 1, 2, n (reference-3dof.md's a1, a2, a3 for n = 3) */

    /* sin/cos of the relative joint angles q_2..q_n at the start of the RK4 step */
    double q_ref[N_JOINTS], s_ref[N_JOINTS], c_ref[N_JOINTS];
    int n_rotated;
} ModelData;

#endif

#endif
