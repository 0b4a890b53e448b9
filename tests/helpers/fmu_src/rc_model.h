/* A one-node RC model shared by the FMI 2 and FMI 3 test FMUs.
 *
 *   C dT/dt = (T_out - T) / R,    q = (T_out - T) / R
 *
 * R: thermal resistance [m2.K/W], C: heat capacity [J/(m2.K)], T0: initial
 * temperature, T_out: input temperature, T: node temperature (all in the same
 * temperature unit), q: heat flux from the input side into the node [W/m2].
 *
 * Within a communication step the input is T_out + dT_out * s (dT_out is the
 * input derivative set by the importer, zero otherwise); the node equation is
 * integrated with classical Runge-Kutta (RK4) sub-steps of at most tau/200,
 * tau = R*C, so that its truncation error is far below the test tolerances.
 */
#ifndef RC_MODEL_H
#define RC_MODEL_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { VR_TIME = 0, VR_R, VR_C, VR_T0, VR_TOUT, VR_T, VR_Q, N_VR };

typedef struct {
    double v[N_VR];  /* values indexed by value reference */
    double dTout;    /* input derivative over the current step */
} RCModel;

static void rc_reset(RCModel *m, double T0) {
    memset(m, 0, sizeof(*m));
    m->v[VR_R] = 0.5;
    m->v[VR_C] = 2.0e4;
    m->v[VR_T0] = T0;
    m->v[VR_TOUT] = T0;
    m->v[VR_T] = T0;
}

static const char *rc_check(const RCModel *m) {
    if (!(m->v[VR_R] > 0.0)) return "parameter R must be positive";
    if (!(m->v[VR_C] > 0.0)) return "parameter C must be positive";
    return NULL;
}

static void rc_initialize(RCModel *m) { m->v[VR_T] = m->v[VR_T0]; }

static double rc_value(const RCModel *m, unsigned vr) {
    if (vr == VR_Q) return (m->v[VR_TOUT] - m->v[VR_T]) / m->v[VR_R];
    return m->v[vr];
}

static double rc_rhs(const RCModel *m, double T, double s) {
    const double u = m->v[VR_TOUT] + m->dTout * s;
    return (u - T) / (m->v[VR_R] * m->v[VR_C]);
}

static void rc_step(RCModel *m, double h) {
    const double tau = m->v[VR_R] * m->v[VR_C];
    long n = (long)ceil(h / (tau / 200.0));
    if (n < 1) n = 1;
    const double dt = h / (double)n;
    double T = m->v[VR_T];
    for (long k = 0; k < n; k++) {
        const double s = k * dt;
        const double k1 = rc_rhs(m, T, s);
        const double k2 = rc_rhs(m, T + 0.5 * dt * k1, s + 0.5 * dt);
        const double k3 = rc_rhs(m, T + 0.5 * dt * k2, s + 0.5 * dt);
        const double k4 = rc_rhs(m, T + dt * k3, s + dt);
        T += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    m->v[VR_T] = T;
    m->v[VR_TOUT] += m->dTout * h;
    m->dTout = 0.0;
    m->v[VR_TIME] += h;
}

#endif
