/* ArmExoPlant: model configuration (identifier, GUID, value references, model data). */
#ifndef CONFIG_H
#define CONFIG_H

/* MODEL_IDENTIFIER_STRING, INSTANTIATION_TOKEN (the GUID), N_VR, the enum vr_...,
 * VR_NAME, VR_CAUSALITY and VR_START: generated from fmus/variables.py. */
#include "variables.h"

#define N_JOINTS 2
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

#endif
