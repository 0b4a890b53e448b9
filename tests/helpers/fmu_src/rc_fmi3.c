/* FMI 3.0 co-simulation wrapper of rc_model.h (temperatures in degrees Celsius). */
#include <stdio.h>
#include "fmi3Functions.h"
#include "rc_model.h"

#ifndef RC_TOKEN
#define RC_TOKEN "{0d6c1b0e-7f2b-4c47-b1a4-5f3f0f6f9a03}"
#endif

typedef struct {
    RCModel m;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

static fmi3Status fail(fmi3Instance c, const char *msg) {
    Instance *i = (Instance *)c;
    if (i && i->log) i->log(i->env, fmi3Error, "logStatusError", msg);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
                                          fmi3Boolean log, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback cb) {
    (void)name; (void)token; (void)res; (void)vis; (void)log; (void)env; (void)cb;
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
                                         fmi3Boolean logOn, fmi3Boolean eventMode, fmi3Boolean earlyReturn,
                                         const fmi3ValueReference req[], size_t nReq,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update) {
    (void)name; (void)res; (void)vis; (void)logOn; (void)eventMode; (void)earlyReturn; (void)req;
    (void)nReq; (void)update;
    if (!token || strcmp(token, RC_TOKEN) != 0) {
        if (log) log(env, fmi3Error, "logStatusError", "wrong instantiation token");
        return NULL;
    }
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->env = env;
    c->log = log;
    rc_reset(&c->m, 20.0);
    return c;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res,
                                               fmi3Boolean vis, fmi3Boolean log, fmi3InstanceEnvironment env,
                                               fmi3LogMessageCallback cb, fmi3ClockUpdateCallback clk,
                                               fmi3LockPreemptionCallback lock,
                                               fmi3UnlockPreemptionCallback unlock) {
    (void)name; (void)token; (void)res; (void)vis; (void)log; (void)env; (void)cb; (void)clk; (void)lock;
    (void)unlock;
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c) { free(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stopDef, fmi3Float64 stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((Instance *)c)->m.v[VR_TIME] = start;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    Instance *i = (Instance *)c;
    const char *msg = rc_check(&i->m);
    if (msg) return fail(c, msg);
    rc_initialize(&i->m);
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) { return fail(c, "not supported"); }
fmi3Status fmi3Terminate(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) { rc_reset(&((Instance *)c)->m, 20.0); return fmi3OK; }

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 v[], size_t nv) {
    if (nvr != nv) return fail(c, "nValueReferences != nValues");
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR) return fail(c, "unknown value reference");
        v[k] = rc_value(&((Instance *)c)->m, vr[k]);
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 v[],
                          size_t nv) {
    if (nvr != nv) return fail(c, "nValueReferences != nValues");
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] < VR_R || vr[k] > VR_TOUT) return fail(c, "variable cannot be set");
        ((Instance *)c)->m.v[vr[k]] = v[k];
    }
    return fmi3OK;
}

#define GET_STUB(NAME, T)                                                                            \
    fmi3Status NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, T v[], size_t nv) {   \
        (void)vr; (void)nvr; (void)v; (void)nv;                                                      \
        return fail(c, "the model has no variables of this type");                                  \
    }
#define SET_STUB(NAME, T)                                                                                \
    fmi3Status NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const T v[], size_t nv) { \
        (void)vr; (void)nvr; (void)v; (void)nv;                                                          \
        return fail(c, "the model has no variables of this type");                                      \
    }
#define TYPE_STUBS(N, T) GET_STUB(fmi3Get##N, T) SET_STUB(fmi3Set##N, T)
TYPE_STUBS(Float32, fmi3Float32)
TYPE_STUBS(Int8, fmi3Int8)
TYPE_STUBS(UInt8, fmi3UInt8)
TYPE_STUBS(Int16, fmi3Int16)
TYPE_STUBS(UInt16, fmi3UInt16)
TYPE_STUBS(Int32, fmi3Int32)
TYPE_STUBS(UInt32, fmi3UInt32)
TYPE_STUBS(Int64, fmi3Int64)
TYPE_STUBS(UInt64, fmi3UInt64)
TYPE_STUBS(Boolean, fmi3Boolean)
TYPE_STUBS(String, fmi3String)

#define NOT_SUPPORTED return fail(c, "not supported")
fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t sz[], fmi3Binary v[],
                         size_t nv) { (void)vr; (void)nvr; (void)sz; (void)v; (void)nv; NOT_SUPPORTED; }
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t sz[],
                         const fmi3Binary v[], size_t nv) { (void)vr; (void)nvr; (void)sz; (void)v; (void)nv; NOT_SUPPORTED; }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock v[]) {
    (void)vr; (void)nvr; (void)v; NOT_SUPPORTED;
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock v[]) {
    (void)vr; (void)nvr; (void)v; NOT_SUPPORTED;
}
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *n) {
    (void)vr; (void)n; NOT_SUPPORTED;
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference d, size_t ed[], fmi3ValueReference ind[],
                                       size_t ei[], fmi3DependencyKind k[], size_t n) {
    (void)d; (void)ed; (void)ind; (void)ei; (void)k; (void)n; NOT_SUPPORTED;
}
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s) { (void)s; NOT_SUPPORTED; }
fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s) { (void)s; NOT_SUPPORTED; }
fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s) { (void)s; NOT_SUPPORTED; }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *n) { (void)s; (void)n; NOT_SUPPORTED; }
fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte b[], size_t n) {
    (void)s; (void)b; (void)n; NOT_SUPPORTED;
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte b[], size_t n, fmi3FMUState *s) {
    (void)s; (void)b; (void)n; NOT_SUPPORTED;
}
#define DERIVATIVE_STUB(NAME)                                                                             \
    fmi3Status NAME(fmi3Instance c, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], \
                    size_t nk, const fmi3Float64 seed[], size_t ns, fmi3Float64 sens[], size_t nsens) {    \
        (void)u; (void)nu; (void)k; (void)nk; (void)seed; (void)ns; (void)sens; (void)nsens;              \
        NOT_SUPPORTED;                                                                                    \
    }
DERIVATIVE_STUB(fmi3GetDirectionalDerivative)
DERIVATIVE_STUB(fmi3GetAdjointDerivative)
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) { NOT_SUPPORTED; }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) { NOT_SUPPORTED; }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
                                  fmi3IntervalQualifier q[]) { (void)vr; (void)n; (void)iv; (void)q; NOT_SUPPORTED; }
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 cnt[],
                                   fmi3UInt64 res[], fmi3IntervalQualifier q[]) {
    (void)vr; (void)n; (void)cnt; (void)res; (void)q; NOT_SUPPORTED;
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s; NOT_SUPPORTED;
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 cnt[],
                                fmi3UInt64 res[]) { (void)vr; (void)n; (void)cnt; (void)res; NOT_SUPPORTED; }
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) {
    (void)vr; (void)n; (void)iv; NOT_SUPPORTED;
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 cnt[],
                                   const fmi3UInt64 res[]) { (void)vr; (void)n; (void)cnt; (void)res; NOT_SUPPORTED; }
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s; NOT_SUPPORTED;
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 cnt[],
                                const fmi3UInt64 res[]) { (void)vr; (void)n; (void)cnt; (void)res; NOT_SUPPORTED; }
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { NOT_SUPPORTED; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *a, fmi3Boolean *b, fmi3Boolean *d, fmi3Boolean *e,
                                    fmi3Boolean *f, fmi3Float64 *g) {
    (void)a; (void)b; (void)d; (void)e; (void)f; (void)g; NOT_SUPPORTED;
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { NOT_SUPPORTED; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *d) {
    (void)a; (void)b; (void)d; NOT_SUPPORTED;
}
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) { (void)t; NOT_SUPPORTED; }
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t n) { (void)x; (void)n; NOT_SUPPORTED; }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; NOT_SUPPORTED;
}
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 x[], size_t n) { (void)x; (void)n; NOT_SUPPORTED; }
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t n) { (void)x; (void)n; NOT_SUPPORTED; }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t n) {
    (void)x; (void)n; NOT_SUPPORTED;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { (void)n; NOT_SUPPORTED; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) { (void)n; NOT_SUPPORTED; }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 ord[], fmi3Float64 v[], size_t nv) {
    (void)vr; (void)nvr; (void)ord; (void)v; (void)nv; NOT_SUPPORTED;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior,
                      fmi3Boolean *eventNeeded, fmi3Boolean *terminate, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastTime) {
    Instance *i = (Instance *)c;
    (void)noSetPrior;
    *eventNeeded = fmi3False;
    *terminate = fmi3False;
    *earlyReturn = fmi3False;
    *lastTime = t;
    if (fabs(t - i->m.v[VR_TIME]) > 1e-9 * (1.0 + fabs(t))) return fail(c, "communication point out of sequence");
    if (!(h > 0.0)) return fail(c, "step size must be positive");
    const char *msg = rc_check(&i->m);
    if (msg) return fail(c, msg);
    rc_step(&i->m, h);
    if (!isfinite(i->m.v[VR_T])) return fail(c, "the node temperature is not finite");
    *lastTime = t + h;
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clk, fmi3Float64 t) {
    (void)clk; (void)t; NOT_SUPPORTED;
}
