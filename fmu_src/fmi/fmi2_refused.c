/*
 * The FMI 2.0 co-simulation functions no native FMU of this project provides (their model
 * descriptions say so: no directional derivatives, canInterpolateInputs = false,
 * maxOutputDerivativeOrder = 0, canRunAsynchronuously = false, never fmi2Pending, no Integer
 * or String status).  Each refuses in every phase with fmi2Error and a log message.
 */
#include "fmi_model.h" /* first: the model's own headers may set feature macros */

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

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
