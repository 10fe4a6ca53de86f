/*
 * The shapes the FMI layers (fmi2_api.c, fmi3_api.c, fmi3_refused.c) share, written once
 * for FMI 2.0 and FMI 3.0.  A layer defines, before including this header:
 *
 *   FMI_STATUS    its status type (fmi2Status, fmi3Status: both number OK..Fatal as AvrStatus)
 *   FMI_INSTANCE  its instance type (fmi2Component, fmi3Instance)
 *
 * and one MASK_<function> per FMI function: the phases it may be called in (its allowed-state
 * table).  Every function begins with the one prologue BEGIN(<function>), which defines `inst`
 * and `call` and refuses the call (logged, Error, nothing changed) outside those phases.
 */
#ifndef AVR_FMI_API_H
#define AVR_FMI_API_H

#include "avr_instance.h"

#include <stdlib.h>

#define FMI_ERROR ((FMI_STATUS)AVR_ERROR)

/* Phase sets the masks of both versions use (FMI 2.0 section 4.2.4, FMI 3.0 section 4.3). */
#define ANY AVR_ANY_PHASE
#define GET_PHASES (AVR_INIT_MODE | AVR_STEP_MODE | AVR_TERMINATED)
#define SET_PHASES (AVR_INSTANTIATED | AVR_INIT_MODE | AVR_STEP_MODE)

/* The one prologue: the instance, the call's name, and its phase check against `mask`. */
#define BEGIN_MASK(fn, mask)                                                \
    AvrInstance *inst = (AvrInstance *)instance;                            \
    static const char call[] = #fn;                                         \
    if (avr_allowed(inst, call, mask) != AVR_OK) return FMI_ERROR;
#define BEGIN(fn) BEGIN_MASK(fn, MASK_##fn)

#define REFUSE(...) return (FMI_STATUS)avr_refuse(inst, call, __VA_ARGS__)

/* Parameters a refusing function never reads (GCC and Clang; other compilers may warn). */
#if defined(__GNUC__)
#define AVR_UNUSED_PARAMETERS_BEGIN _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wunused-parameter\"")
#define AVR_UNUSED_PARAMETERS_END _Pragma("GCC diagnostic pop")
#else
#define AVR_UNUSED_PARAMETERS_BEGIN
#define AVR_UNUSED_PARAMETERS_END
#endif

/* A function this FMU does not provide (the model description says so): refused in every phase
 * (mask 0) with the reason logged.  NOT_PROVIDED0 for the functions without further parameters. */
#define NOT_PROVIDED(fn, ...)                                       \
    AVR_UNUSED_PARAMETERS_BEGIN                                     \
    FMI_STATUS fn(FMI_INSTANCE instance, __VA_ARGS__) {             \
        BEGIN_MASK(fn, 0u)                                          \
        return FMI_ERROR;                                           \
    }                                                               \
    AVR_UNUSED_PARAMETERS_END
#define NOT_PROVIDED0(fn)                                           \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN_MASK(fn, 0u)                                          \
        return FMI_ERROR;                                           \
    }

/* Life cycle without arguments, the same in both versions. */
#define FREE_INSTANCE(fn)                                           \
    void fn(FMI_INSTANCE instance) {                                \
        AvrInstance *inst = (AvrInstance *)instance;                \
        if (inst == NULL) return;                                   \
        void *callbacks = inst->env;                                \
        avr_free_instance(inst);                                    \
        free(callbacks);                                            \
    }
#define EXIT_INITIALIZATION_MODE(fn)                                \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        return (FMI_STATUS)avr_exit_init(inst, call);               \
    }
#define TERMINATE(fn)                                               \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        inst->phase = AVR_TERMINATED;                               \
        return (FMI_STATUS)AVR_OK;                                  \
    }
#define RESET(fn)                                                   \
    FMI_STATUS fn(FMI_INSTANCE instance) {                          \
        BEGIN(fn)                                                   \
        avr_reset(inst);                                            \
        return (FMI_STATUS)AVR_OK;                                  \
    }

/* The six FMU-state functions over avr_state.c; STATE is the version's FMU-state type, BYTE
 * its byte type, and the names its spellings (FMI 2.0 "FMUstate", FMI 3.0 "FMUState"). */
#define FMUSTATE_FUNCTIONS(STATE, BYTE, GET, SET, FREE, SIZE, SERIALIZE, DESERIALIZE)                         \
    FMI_STATUS GET(FMI_INSTANCE instance, STATE *state) {                                                     \
        BEGIN(GET)                                                                                            \
        return (FMI_STATUS)avr_fmustate_get(inst, call, state);                                               \
    }                                                                                                         \
    FMI_STATUS SET(FMI_INSTANCE instance, STATE state) {                                                      \
        BEGIN(SET)                                                                                            \
        return (FMI_STATUS)avr_fmustate_set(inst, call, state);                                               \
    }                                                                                                         \
    FMI_STATUS FREE(FMI_INSTANCE instance, STATE *state) {                                                    \
        BEGIN(FREE)                                                                                           \
        avr_fmustate_free(state);                                                                             \
        return (FMI_STATUS)AVR_OK;                                                                            \
    }                                                                                                         \
    FMI_STATUS SIZE(FMI_INSTANCE instance, STATE state, size_t *size) {                                       \
        BEGIN(SIZE)                                                                                           \
        return (FMI_STATUS)avr_fmustate_size(inst, call, state, size);                                        \
    }                                                                                                         \
    FMI_STATUS SERIALIZE(FMI_INSTANCE instance, STATE state, BYTE serializedState[], size_t size) {           \
        BEGIN(SERIALIZE)                                                                                      \
        return (FMI_STATUS)avr_fmustate_serialize(inst, call, state, (unsigned char *)serializedState, size); \
    }                                                                                                         \
    FMI_STATUS DESERIALIZE(FMI_INSTANCE instance, const BYTE serializedState[], size_t size, STATE *state) {  \
        BEGIN(DESERIALIZE)                                                                                    \
        return (FMI_STATUS)avr_fmustate_deserialize(inst, call, (const unsigned char *)serializedState, size, \
                                                    state);                                                   \
    }

#endif
