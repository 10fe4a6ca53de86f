/*
 * What the FMI 2.0 layer of every native FMU of this project has the same: the inquiry
 * functions, the host's callbacks and the logger over them, doStep and the status functions
 * over the model's instance (fmi_model.h), and the co-simulation functions no
 * native FMU provides (their model descriptions say so: no directional derivatives,
 * canInterpolateInputs = false, maxOutputDerivativeOrder = 0, canRunAsynchronuously = false,
 * never fmi2Pending, no Integer or String status), each refused in every phase with fmi2Error
 * and a log message.
 */
#include "fmi_model.h" /* first: the model's own headers may set feature macros */

#include <stdlib.h>

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2CallbackFunctions *fmi2_callbacks(const fmi2CallbackFunctions *functions) {
    if (functions == NULL) return NULL;
    fmi2CallbackFunctions *cb = malloc(sizeof *cb);
    if (cb != NULL) *cb = *functions;
    return cb;
}

void fmi2_log(const FmiModelInstance *inst, FmiModelStatus status, const char *category, const char *message) {
    const fmi2CallbackFunctions *cb = (const fmi2CallbackFunctions *)inst->env;
    /* the message goes as an argument, never as the format string */
    if (cb != NULL && cb->logger != NULL)
        cb->logger(cb->componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

/* ---- stepping and status (the model steps: fmi_model_do_step) ------------------------------------ */
fmi2Status fmi2DoStep(fmi2Component instance, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN(fmi2DoStep)
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)fmi_model_do_step(inst, call, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2GetRealStatus(fmi2Component instance, const fmi2StatusKind s, fmi2Real *value) {
    BEGIN(fmi2GetRealStatus)
    if (s != fmi2LastSuccessfulTime || value == NULL) REFUSE("only fmi2LastSuccessfulTime is provided");
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component instance, const fmi2StatusKind s, fmi2Boolean *value) {
    BEGIN(fmi2GetBooleanStatus)
    if (s != fmi2Terminated || value == NULL) REFUSE("only fmi2Terminated is provided");
    *value = fmi2False; /* no native FMU asks to end the simulation */
    return fmi2OK;
}

/* ---- not provided ------------------------------------------------------------------------------ */
NOT_PROVIDED(fmi2GetDirectionalDerivative, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
             const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
NOT_PROVIDED(fmi2SetRealInputDerivatives, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[],
             const fmi2Real value[])
NOT_PROVIDED(fmi2GetRealOutputDerivatives, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[],
             fmi2Real value[])
NOT_PROVIDED0(fmi2CancelStep)
NOT_PROVIDED(fmi2GetStatus, const fmi2StatusKind s, fmi2Status *value)
NOT_PROVIDED(fmi2GetIntegerStatus, const fmi2StatusKind s, fmi2Integer *value)
NOT_PROVIDED(fmi2GetStringStatus, const fmi2StatusKind s, fmi2String *value)
