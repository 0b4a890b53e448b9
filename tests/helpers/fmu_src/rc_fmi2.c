/* FMI 2.0 co-simulation wrapper of rc_model.h (temperatures in kelvin). */
#include <stdio.h>
#include "fmi2Functions.h"
#include "rc_model.h"

#ifndef RC_GUID
#define RC_GUID "{5b0c7f55-3a55-4a8e-9c1e-2f6a1f3e0c02}"
#endif

typedef struct {
    RCModel m;
    fmi2CallbackFunctions cb;
    char name[64];
} Instance;

static fmi2Status fail(Instance *c, const char *msg) {
    if (c->cb.logger) c->cb.logger(c->cb.componentEnvironment, c->name, fmi2Error, "logStatusError", "%s", msg);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)resources; (void)visible; (void)loggingOn;
    if (!cb || type != fmi2CoSimulation || !guid || strcmp(guid, RC_GUID) != 0) return NULL;
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->cb = *cb;
    snprintf(c->name, sizeof(c->name), "%s", name ? name : "RCNode");
    rc_reset(&c->m, 293.15);
    return c;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDef, fmi2Real stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((Instance *)c)->m.v[VR_TIME] = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *i = (Instance *)c;
    const char *msg = rc_check(&i->m);
    if (msg) return fail(i, msg);
    rc_initialize(&i->m);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { rc_reset(&((Instance *)c)->m, 293.15); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Instance *i = (Instance *)c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] < VR_R || vr[k] >= N_VR) return fail(i, "unknown value reference");
        value[k] = rc_value(&i->m, vr[k]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Instance *i = (Instance *)c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] < VR_R || vr[k] > VR_TOUT) return fail(i, "variable cannot be set");
        i->m.v[vr[k]] = value[k];
    }
    return fmi2OK;
}

#define NO_SUCH_TYPE(NAME, T, CONST)                                                             \
    fmi2Status NAME(fmi2Component c, const fmi2ValueReference vr[], size_t n, CONST T value[]) { \
        (void)vr; (void)n; (void)value;                                                          \
        return fail((Instance *)c, "the model has no variables of this type");                  \
    }
NO_SUCH_TYPE(fmi2GetInteger, fmi2Integer, )
NO_SUCH_TYPE(fmi2GetBoolean, fmi2Boolean, )
NO_SUCH_TYPE(fmi2GetString, fmi2String, )
NO_SUCH_TYPE(fmi2SetInteger, fmi2Integer, const)
NO_SUCH_TYPE(fmi2SetBoolean, fmi2Boolean, const)
NO_SUCH_TYPE(fmi2SetString, fmi2String, const)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return fail((Instance *)c, "not supported"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; return fail((Instance *)c, "not supported"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return fail((Instance *)c, "not supported"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)s; (void)n; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)s; (void)b; (void)n; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)s; (void)b; (void)n; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference k[], size_t nk, const fmi2Real dk[],
                                        fmi2Real du[]) {
    (void)u; (void)nu; (void)k; (void)nk; (void)dk; (void)du;
    return fail((Instance *)c, "not supported");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *i = (Instance *)c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != VR_TOUT || order[k] != 1) return fail(i, "only first derivatives of T_out");
        i->m.dTout = value[k];
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)n; (void)order; (void)value;
    return fail((Instance *)c, "not supported");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *i = (Instance *)c;
    (void)noSetPrior;
    if (fabs(t - i->m.v[VR_TIME]) > 1e-9 * (1.0 + fabs(t))) return fail(i, "communication point out of sequence");
    if (!(h > 0.0)) return fail(i, "step size must be positive");
    const char *msg = rc_check(&i->m);
    if (msg) return fail(i, msg);
    rc_step(&i->m, h);
    if (!isfinite(i->m.v[VR_T])) return fail(i, "the node temperature is not finite");
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { return fail((Instance *)c, "not supported"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s; (void)v; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s; (void)v; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s; (void)v; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s; (void)v; return fail((Instance *)c, "not supported");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s; (void)v; return fail((Instance *)c, "not supported");
}
