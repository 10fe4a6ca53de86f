/*
 * The regulator's FMI functions whose shape both FMI versions share (fmi2_api.c, fmi3_api.c),
 * over the shared FMI layer (fmu_src/fmi/fmi_layer.h: the prologue BEGIN, REFUSE, NOT_PROVIDED,
 * the life-cycle shapes).  A layer defines FMI_STATUS and FMI_INSTANCE before including this.
 */
#ifndef AVR_FMI_API_H
#define AVR_FMI_API_H

#include "fmi_layer.h"

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
