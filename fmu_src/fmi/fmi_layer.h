/*
 * The FMI layer the native FMUs share (the regulator's fmi2_api.c/fmi3_api.c, CommandSource's
 * cmdsrc_fmi2.c/cmdsrc_fmi3.c, and fmi2_refused.c/fmi3_refused.c beside this header), written
 * once for both models and both FMI versions.  A layer defines, before including this header:
 *
 *   FMI_STATUS    its status type (fmi2Status, fmi3Status: both number OK..Fatal as 0..4)
 *   FMI_INSTANCE  its instance type (fmi2Component, fmi3Instance)
 *
 * and the model's fmi_model.h (found beside its sources) says what an instance is:
 *
 *   FmiModelInstance                           the model's instance type (phase, env, name, time)
 *   fmi_model_allowed(inst, call, mask)        0 if inst is in one of the phases of mask, else
 *                                              the refusal (logged) as a nonzero status
 *   fmi_model_refuse(inst, call, fmt, ...)     logs "<call> refused: ..." and returns Error
 *   fmi_model_free(inst)                       frees the instance (not the FMI layer's callbacks)
 *   fmi_model_reset(inst)                      back to Instantiated with the start values
 *
 * Every function begins with the one prologue BEGIN(<function>): it defines `inst` and `call`
 * and refuses the call (logged, Error, nothing changed) outside the phases of its
 * FMI_MASK_<function>, generated from fmu_src/fmi/phase_rules.py into fmi_phase_rules.h.
 */
#ifndef FMI_LAYER_H
#define FMI_LAYER_H

#include <stdlib.h>

#include "fmi_model.h"
#include "fmi_phase_rules.h"

#define FMI_OK ((FMI_STATUS)0)
#define FMI_ERROR ((FMI_STATUS)3)

/* The one prologue: the instance, the call's name, and its phase check against `mask`. */
#define BEGIN_MASK(fn, mask)                                                \
    FmiModelInstance *inst = (FmiModelInstance *)instance;                  \
    static const char call[] = #fn;                                         \
    if (fmi_model_allowed(inst, call, (mask)) != 0) return FMI_ERROR;
#define BEGIN(fn) BEGIN_MASK(fn, FMI_MASK_##fn)

#define REFUSE(...) return (FMI_STATUS)fmi_model_refuse(inst, call, __VA_ARGS__)

/* Parameters a refusing function never reads (GCC and Clang; other compilers may warn). */
#if defined(__GNUC__)
#define FMI_UNUSED_PARAMETERS_BEGIN _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wunused-parameter\"")
#define FMI_UNUSED_PARAMETERS_END _Pragma("GCC diagnostic pop")
#else
#define FMI_UNUSED_PARAMETERS_BEGIN
#define FMI_UNUSED_PARAMETERS_END
#endif

/* A function this FMU does not provide (the model description says so): refused in every phase
 * (mask 0) with the reason logged.  NOT_PROVIDED0 for the functions without further parameters. */
#define NOT_PROVIDED(fn, ...)                                       \
    FMI_UNUSED_PARAMETERS_BEGIN                                     \
    FMI_STATUS fn(FMI_INSTANCE instance, __VA_ARGS__) {             \
        BEGIN_MASK(fn, 0u)                                          \
        return FMI_ERROR;                                           \
    }                                                               \
    FMI_UNUSED_PARAMETERS_END
#define NOT_PROVIDED0(fn)                                           \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN_MASK(fn, 0u)                                          \
        return FMI_ERROR;                                           \
    }

/* FMI 3.0 getters and setters of a type the model has no variables of: nothing to get or set
 * is fine, anything else refused. */
#define NO_VARIABLES(fn, ctype, type_name)                                                                     \
    FMI_STATUS fn(FMI_INSTANCE instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,  \
                  ctype values[], size_t nValues) {                                                            \
        BEGIN(fn)                                                                                              \
        (void)valueReferences, (void)values, (void)nValues;                                                    \
        if (nValueReferences == 0) return FMI_OK;                                                              \
        REFUSE("this FMU has no %s variables", type_name);                                                     \
    }
#define NO_GET_SET(T)                                    \
    NO_VARIABLES(fmi3Get##T, fmi3##T, #T)                \
    NO_VARIABLES(fmi3Set##T, const fmi3##T, #T)

/* Life cycle without arguments, the same in both versions and both models. */
#define FREE_INSTANCE(fn)                                           \
    void fn(FMI_INSTANCE instance) {                                \
        FmiModelInstance *inst = (FmiModelInstance *)instance;      \
        if (inst == NULL) return;                                   \
        void *callbacks = inst->env;                                \
        fmi_model_free(inst);                                       \
        free(callbacks);                                            \
    }
#define TERMINATE(fn)                                               \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        inst->phase = FMI_TERMINATED;                               \
        return FMI_OK;                                              \
    }
#define RESET(fn)                                                   \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        fmi_model_reset(inst);                                      \
        return FMI_OK;                                              \
    }

#endif
