/*
 * What the shared FMI layer (fmi_layer.h) needs of CommandSource: its instance and the checks
 * of cmdsrc.c.
 */
#ifndef FMI_MODEL_H
#define FMI_MODEL_H

#include "cmdsrc.h"

typedef CsInstance FmiModelInstance;
typedef CsStatus FmiModelStatus;
#define fmi_model_allowed cs_allowed
#define fmi_model_refuse cs_refuse
#define fmi_model_free cs_free
#define fmi_model_check_categories cs_check_categories
#define fmi_model_exit_init cs_exit_init
#define fmi_model_do_step cs_do_step
#define fmi_model_reset cs_reset

#endif
