/*
 * What the shared FMI layer (fmi_layer.h) needs of the regulator: its instance and the checks
 * of avr_instance.c.
 */
#ifndef FMI_MODEL_H
#define FMI_MODEL_H

#include "avr_instance.h" /* first: see avr_types.h */

typedef AvrInstance FmiModelInstance;
typedef AvrStatus FmiModelStatus;
#define fmi_model_allowed avr_allowed
#define fmi_model_refuse avr_refuse
#define fmi_model_free avr_free_instance
#define fmi_model_check_categories avr_check_categories
#define fmi_model_exit_init avr_exit_init
#define fmi_model_do_step avr_do_step
#define fmi_model_reset avr_reset
#define fmi_model_check_get avr_check_get
#define fmi_model_check_set avr_check_set
#define FMI_MODEL_REAL AVR_REAL
#define fmi_model_fmustate_get avr_fmustate_get
#define fmi_model_fmustate_set avr_fmustate_set
#define fmi_model_fmustate_free avr_fmustate_free
#define fmi_model_fmustate_size avr_fmustate_size
#define fmi_model_fmustate_serialize avr_fmustate_serialize
#define fmi_model_fmustate_deserialize avr_fmustate_deserialize

#endif
