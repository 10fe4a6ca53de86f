/*
 * The FMI layer the native FMUs share (the regulator's fmi2_api.c/fmi3_api.c, CommandSource's
 * cmdsrc_fmi2.c/cmdsrc_fmi3.c, the native CassiePlant's fmi2_plant.c/fmi3_plant.c, and
 * fmi2_common.c/fmi3_common.c beside this header: what every native FMU's layer has the same),
 * written once for the models and both FMI versions.  A layer defines, before including this header:
 *
 *   FMI_STATUS    its status type (fmi2Status, fmi3Status: both number OK..Fatal as 0..4)
 *   FMI_INSTANCE  its instance type (fmi2Component, fmi3Instance)
 *
 * and the model's fmi_model.h (found beside its sources) says what an instance is:
 *
 *   FmiModelInstance                           the model's instance type (phase, env, name)
 *   FmiModelStatus                             its status type (OK..Fatal as 0..4)
 *   fmi_model_allowed(inst, call, mask)        0 if inst is in one of the phases of mask, else
 *                                              the refusal (logged) as a nonzero status
 *   fmi_model_refuse(inst, call, fmt, ...)     logs "<call> refused: ..." and returns Error
 *   fmi_model_free(inst)                       frees the instance (not the FMI layer's callbacks)
 *   fmi_model_exit_init(inst, call)            leaves Initialization Mode (status as 0..4)
 *   fmi_model_do_step(inst, call, t, h)        one communication step (status as 0..4; inst->time
 *                                              is then the end of the last successful step)
 *   fmi_model_reset(inst)                      back to Instantiated with the start values
 *   fmi_model_check_categories(inst, call, n, categories)
 *                                              0 if fmi*SetDebugLogging may take these log
 *                                              categories, else the refusal as a nonzero status
 *   FMI_MODEL_HAS_STRINGS                      (optional) defined if the model has String
 *                                              variables: its layer then defines fmi3GetString
 *                                              and fmi3SetString, not fmi3_common.c
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
/* fmi*SetDebugLogging: the model checks the categories, the instance keeps loggingOn. */
#define SET_DEBUG_LOGGING(fn, BOOLEAN, STRING)                                                            \
    FMI_STATUS fn(FMI_INSTANCE instance, BOOLEAN loggingOn, size_t nCategories, const STRING categories[]) { \
        BEGIN(fn)                                                                                         \
        if (fmi_model_check_categories(inst, call, nCategories, categories) != 0) return FMI_ERROR;       \
        inst->logging_on = loggingOn == 1;                                                                \
        return FMI_OK;                                                                                    \
    }
#define EXIT_INITIALIZATION_MODE(fn)                                \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        return (FMI_STATUS)fmi_model_exit_init(inst, call);         \
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

/* ---- variables: the model keeps every value as a double in inst->values; fmi_model.h maps
 * fmi_model_check_get(inst, call, vr, n, type) and fmi_model_check_set(inst, call, vr, type, x)
 * (0 if the call may get vr[0..n-1] / set vr to x).  All or nothing: every value is checked
 * before any is stored. ------------------------------------------------------------------------ */
/* FMI 2.0: FROM_DOUBLE converts a stored double to ctype, TO_DOUBLE a given value to a double. */
#define FMI2_GETTER(fn, ctype, type, FROM_DOUBLE)                                                        \
    FMI_STATUS fn(FMI_INSTANCE instance, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {     \
        BEGIN(fn)                                                                                        \
        if (nvr > 0 && value == NULL) REFUSE("NULL value array with nvr = %zu", nvr);                    \
        if (fmi_model_check_get(inst, call, vr, nvr, type) != 0) return FMI_ERROR;                       \
        for (size_t i = 0; i < nvr; ++i) value[i] = FROM_DOUBLE(inst->values[vr[i]]);                    \
        return FMI_OK;                                                                                   \
    }
#define FMI2_SETTER(fn, ctype, type, TO_DOUBLE)                                                          \
    FMI_STATUS fn(FMI_INSTANCE instance, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) { \
        BEGIN(fn)                                                                                        \
        if (nvr > 0 && (vr == NULL || value == NULL)) REFUSE("NULL vr or value array with nvr = %zu", nvr); \
        for (size_t i = 0; i < nvr; ++i)                                                                 \
            if (fmi_model_check_set(inst, call, vr[i], type, TO_DOUBLE(value[i])) != 0) return FMI_ERROR; \
        for (size_t i = 0; i < nvr; ++i) inst->values[vr[i]] = TO_DOUBLE(value[i]);                     \
        return FMI_OK;                                                                                   \
    }
/* FMI 3.0 scalars (fmi3_check_counts: nValues equals nValueReferences, no NULL array); the
 * independent variable time has the value reference TIME_VR (the model's variable count),
 * readable as Float64 and never settable.  READ(values, i) reads element i as a double. */
#define FMI3_GET_FLOAT64(TIME_VR)                                                                              \
    FMI_STATUS fmi3GetFloat64(FMI_INSTANCE instance, const fmi3ValueReference valueReferences[],               \
                              size_t nValueReferences, fmi3Float64 values[], size_t nValues) {                 \
        BEGIN(fmi3GetFloat64)                                                                                  \
        if (fmi3_check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != 0) return FMI_ERROR; \
        for (size_t i = 0; i < nValueReferences; ++i)                                                          \
            if (valueReferences[i] != (TIME_VR) &&                                                             \
                fmi_model_check_get(inst, call, &valueReferences[i], 1, FMI_MODEL_REAL) != 0)                  \
                return FMI_ERROR;                                                                              \
        for (size_t i = 0; i < nValueReferences; ++i)                                                          \
            values[i] = valueReferences[i] == (TIME_VR) ? inst->time : inst->values[valueReferences[i]];       \
        return FMI_OK;                                                                                         \
    }
#define FMI3_GETTER(fn, ctype, type, FROM_DOUBLE)                                                              \
    FMI_STATUS fn(FMI_INSTANCE instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,  \
                  ctype values[], size_t nValues) {                                                            \
        BEGIN(fn)                                                                                              \
        if (fmi3_check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != 0 ||          \
            fmi_model_check_get(inst, call, valueReferences, nValueReferences, type) != 0)                     \
            return FMI_ERROR;                                                                                  \
        for (size_t i = 0; i < nValueReferences; ++i) values[i] = FROM_DOUBLE(inst->values[valueReferences[i]]); \
        return FMI_OK;                                                                                         \
    }
#define FMI3_SETTER(fn, ctype, type, READ, TIME_VR)                                                            \
    FMI_STATUS fn(FMI_INSTANCE instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,  \
                  const ctype values[], size_t nValues) {                                                      \
        BEGIN(fn)                                                                                              \
        if (fmi3_check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != 0) return FMI_ERROR; \
        for (size_t i = 0; i < nValueReferences; ++i) {                                                        \
            if (valueReferences[i] == (TIME_VR)) REFUSE("time is the independent variable and cannot be set"); \
            if (fmi_model_check_set(inst, call, valueReferences[i], type, READ(values, i)) != 0) return FMI_ERROR; \
        }                                                                                                      \
        for (size_t i = 0; i < nValueReferences; ++i) inst->values[valueReferences[i]] = READ(values, i);     \
        return FMI_OK;                                                                                         \
    }
#define FMI3_READ_NUMBER(values, i) ((double)(values)[i])
/* A Boolean read as its byte: a bool other than 0/1 is refused by the range check, not UB. */
#define FMI3_READ_BYTE(values, i) ((double)((const unsigned char *)(values))[i])

/* Every getter and setter of a model's Real/Integer/Boolean variables (its types REAL, INTEGER,
 * BOOLEAN).  FMI 2.0: BOOL_TO_DOUBLE reads an fmi2Boolean (FMI_TO_DOUBLE: any value other than
 * 0/1 is then refused by the range check).  FMI 3.0: TIME_VR is time's value reference. */
#define FMI_TO_DOUBLE(x) ((double)(x))
#define FMI2_AS_REAL(x) (x)
#define FMI2_AS_INTEGER(x) ((fmi2Integer)(x))
#define FMI2_AS_BOOLEAN(x) ((x) != 0.0 ? fmi2True : fmi2False)
#define FMI2_NUMERIC_VARIABLES(REAL, INTEGER, BOOLEAN, BOOL_TO_DOUBLE)       \
    FMI2_GETTER(fmi2GetReal, fmi2Real, REAL, FMI2_AS_REAL)                   \
    FMI2_GETTER(fmi2GetInteger, fmi2Integer, INTEGER, FMI2_AS_INTEGER)       \
    FMI2_GETTER(fmi2GetBoolean, fmi2Boolean, BOOLEAN, FMI2_AS_BOOLEAN)       \
    FMI2_SETTER(fmi2SetReal, fmi2Real, REAL, FMI_TO_DOUBLE)                  \
    FMI2_SETTER(fmi2SetInteger, fmi2Integer, INTEGER, FMI_TO_DOUBLE)         \
    FMI2_SETTER(fmi2SetBoolean, fmi2Boolean, BOOLEAN, BOOL_TO_DOUBLE)
#define FMI3_AS_INT32(x) ((fmi3Int32)(x))
#define FMI3_AS_BOOLEAN(x) ((x) != 0.0)
#define FMI3_NUMERIC_VARIABLES(REAL, INTEGER, BOOLEAN, TIME_VR)                                  \
    FMI3_GET_FLOAT64(TIME_VR)                                                                    \
    FMI3_GETTER(fmi3GetInt32, fmi3Int32, INTEGER, FMI3_AS_INT32)                                 \
    FMI3_GETTER(fmi3GetBoolean, fmi3Boolean, BOOLEAN, FMI3_AS_BOOLEAN)                           \
    FMI3_SETTER(fmi3SetFloat64, fmi3Float64, REAL, FMI3_READ_NUMBER, TIME_VR)                    \
    FMI3_SETTER(fmi3SetInt32, fmi3Int32, INTEGER, FMI3_READ_NUMBER, TIME_VR)                     \
    FMI3_SETTER(fmi3SetBoolean, fmi3Boolean, BOOLEAN, FMI3_READ_BYTE, TIME_VR)

/* ---- FMU state: the six functions over the model's blob functions (fmi_model.h maps
 * fmi_model_fmustate_{get,set,free,size,serialize,deserialize}).  STATE is the version's
 * FMU-state type, BYTE its byte type, the names its spellings ("FMUstate", "FMUState"). ------- */
#define FMUSTATE_FUNCTIONS(STATE, BYTE, GET, SET, FREE, SIZE, SERIALIZE, DESERIALIZE)                         \
    FMI_STATUS GET(FMI_INSTANCE instance, STATE *state) {                                                     \
        BEGIN(GET)                                                                                            \
        return (FMI_STATUS)fmi_model_fmustate_get(inst, call, (void **)state);                                \
    }                                                                                                         \
    FMI_STATUS SET(FMI_INSTANCE instance, STATE state) {                                                      \
        BEGIN(SET)                                                                                            \
        return (FMI_STATUS)fmi_model_fmustate_set(inst, call, state);                                         \
    }                                                                                                         \
    FMI_STATUS FREE(FMI_INSTANCE instance, STATE *state) {                                                    \
        BEGIN(FREE)                                                                                           \
        fmi_model_fmustate_free((void **)state);                                                              \
        return FMI_OK;                                                                                        \
    }                                                                                                         \
    FMI_STATUS SIZE(FMI_INSTANCE instance, STATE state, size_t *size) {                                       \
        BEGIN(SIZE)                                                                                           \
        return (FMI_STATUS)fmi_model_fmustate_size(inst, call, state, size);                                  \
    }                                                                                                         \
    FMI_STATUS SERIALIZE(FMI_INSTANCE instance, STATE state, BYTE serializedState[], size_t size) {           \
        BEGIN(SERIALIZE)                                                                                      \
        return (FMI_STATUS)fmi_model_fmustate_serialize(inst, call, state, (unsigned char *)serializedState,  \
                                                        size);                                                \
    }                                                                                                         \
    FMI_STATUS DESERIALIZE(FMI_INSTANCE instance, const BYTE serializedState[], size_t size, STATE *state) {  \
        BEGIN(DESERIALIZE)                                                                                    \
        return (FMI_STATUS)fmi_model_fmustate_deserialize(inst, call, (const unsigned char *)serializedState, \
                                                          size, (void **)state);                              \
    }

/* ---- fmi2_common.c / fmi3_common.c: the host's callbacks, kept as an instance's env ---------- */
#ifdef fmi2Version
/* A copy of the host's callbacks (malloc'd; NULL if functions is NULL or memory is out). */
fmi2CallbackFunctions *fmi2_callbacks(const fmi2CallbackFunctions *functions);
/* The model's logger for an instance whose env is an fmi2_callbacks copy. */
void fmi2_log(const FmiModelInstance *inst, FmiModelStatus status, const char *category, const char *message);
#endif
#ifdef fmi3Version
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} FmiCallbacks3;
/* The host's environment and logger (malloc'd; NULL if memory is out). */
FmiCallbacks3 *fmi3_callbacks(fmi3InstanceEnvironment env, fmi3LogMessageCallback log);
/* The model's logger for an instance whose env is an fmi3_callbacks copy. */
void fmi3_log(const FmiModelInstance *inst, FmiModelStatus status, const char *category, const char *message);
/* Why fmi3InstantiateCoSimulation with these options cannot give an instance of a native FMU of
 * this project (no event mode, no intermediate variables), or NULL. */
const char *fmi3_cosim_problem(fmi3Boolean eventModeUsed, size_t nRequiredIntermediateVariables);
/* 0 if an FMI 3.0 getter's or setter's arrays fit (nValues == nvr, no NULL array with nvr > 0),
 * else the refusal (logged, Error). */
fmi3Status fmi3_check_counts(FmiModelInstance *inst, const char *call, const fmi3ValueReference vr[], size_t nvr,
                             const void *values, size_t nValues);
#endif


#endif
