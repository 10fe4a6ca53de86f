/*
 * What the shared FMI layer (fmu_src/fmi/fmi_layer.h) needs of the native CassiePlant: its
 * instance and the checks of cp_instance.c.
 */
#ifndef FMI_MODEL_H
#define FMI_MODEL_H

#include "cp_instance.h" /* first: the floating-point contract */

typedef CpInstance FmiModelInstance;
typedef CpStatus FmiModelStatus;
#define fmi_model_allowed cp_allowed
#define fmi_model_refuse cp_refuse
#define fmi_model_free cp_free_instance
#define fmi_model_check_categories cp_check_categories
#define fmi_model_exit_init cp_exit_init
#define fmi_model_do_step cp_do_step
#define fmi_model_reset cp_reset
#define fmi_model_check_get cp_check_get
#define fmi_model_check_set cp_check_set
#define FMI_MODEL_REAL CP_REAL
#define fmi_model_fmustate_get cp_fmustate_get
#define fmi_model_fmustate_set cp_fmustate_set
#define fmi_model_fmustate_free cp_fmustate_free
#define fmi_model_fmustate_size cp_fmustate_size
#define fmi_model_fmustate_serialize cp_fmustate_serialize
#define fmi_model_fmustate_deserialize cp_fmustate_deserialize
/* The plant has a String variable (cassie_model): fmi3_common.c leaves fmi3GetString and
 * fmi3SetString to the model's layer. */
#define FMI_MODEL_HAS_STRINGS 1

#endif
