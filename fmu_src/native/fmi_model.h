/*
 * What the shared FMI layer (fmi_layer.h) needs of the regulator: its instance and the checks
 * of avr_instance.c.
 */
#ifndef FMI_MODEL_H
#define FMI_MODEL_H

#include "avr_instance.h" /* first: see avr_types.h */

typedef AvrInstance FmiModelInstance;
#define fmi_model_allowed avr_allowed
#define fmi_model_refuse avr_refuse
#define fmi_model_free avr_free_instance
#define fmi_model_reset avr_reset

#endif
