/*
 * MuJoCo's C API, linked at build time on Linux (the FMU's libmujoco.so.* beside it, found
 * through the run path $ORIGIN) and loaded at run time on Windows: the Windows loader looks for
 * a DLL's dependencies beside the host program, not beside the DLL, so the FMU's library loads
 * the mujoco.dll of its own folder itself (cp_mujoco_load) and calls MuJoCo through the
 * pointers declared here.  Include after mujoco.h; every file that calls MuJoCo includes it
 * (through cassie_ctrl.h).
 */
#ifndef MJ_DYN_H
#define MJ_DYN_H

#define CP_MJ_FUNCTIONS(X)                                                                        \
    X(mj_parseXML) X(mj_compile) X(mjs_getError) X(mj_deleteSpec) X(mj_deleteModel) X(mj_name2id) \
    X(mj_id2name) X(mjs_addKey) X(mjs_setName) X(mjs_setDouble) X(mj_makeData) X(mj_setConst)     \
    X(mj_deleteData) X(mj_resetData) X(mj_resetDataKeyframe) X(mj_kinematics) X(mj_forward)      \
    X(mj_step) X(mj_contactForce) X(mj_stateSize) X(mj_getState) X(mj_setState) X(mju_quat2Mat)  \
    X(mju_axisAngle2Quat) X(mjs_findBody) X(mjs_firstChild) X(mjs_nextChild) X(mjs_asGeom)       \
    X(mjs_addHField) X(mjs_setFloat) X(mjs_addGeom) X(mjs_setString) X(mjs_delete)

/* 0 once MuJoCo's functions can be called, else -1 with the reason in err. */
int cp_mujoco_load(char *err, int errlen);

#if defined(_WIN32)
#define CP_MJ_DECLARE(f) extern __typeof__(&f) cpmj_##f;
CP_MJ_FUNCTIONS(CP_MJ_DECLARE)
#define mj_parseXML (*cpmj_mj_parseXML)
#define mj_compile (*cpmj_mj_compile)
#define mjs_getError (*cpmj_mjs_getError)
#define mj_deleteSpec (*cpmj_mj_deleteSpec)
#define mj_deleteModel (*cpmj_mj_deleteModel)
#define mj_name2id (*cpmj_mj_name2id)
#define mj_id2name (*cpmj_mj_id2name)
#define mjs_addKey (*cpmj_mjs_addKey)
#define mjs_setName (*cpmj_mjs_setName)
#define mjs_setDouble (*cpmj_mjs_setDouble)
#define mj_makeData (*cpmj_mj_makeData)
#define mj_setConst (*cpmj_mj_setConst)
#define mj_deleteData (*cpmj_mj_deleteData)
#define mj_resetData (*cpmj_mj_resetData)
#define mj_resetDataKeyframe (*cpmj_mj_resetDataKeyframe)
#define mj_kinematics (*cpmj_mj_kinematics)
#define mj_forward (*cpmj_mj_forward)
#define mj_step (*cpmj_mj_step)
#define mj_contactForce (*cpmj_mj_contactForce)
#define mj_stateSize (*cpmj_mj_stateSize)
#define mj_getState (*cpmj_mj_getState)
#define mj_setState (*cpmj_mj_setState)
#define mju_quat2Mat (*cpmj_mju_quat2Mat)
#define mju_axisAngle2Quat (*cpmj_mju_axisAngle2Quat)
#define mjs_findBody (*cpmj_mjs_findBody)
#define mjs_firstChild (*cpmj_mjs_firstChild)
#define mjs_nextChild (*cpmj_mjs_nextChild)
#define mjs_asGeom (*cpmj_mjs_asGeom)
#define mjs_addHField (*cpmj_mjs_addHField)
#define mjs_setFloat (*cpmj_mjs_setFloat)
#define mjs_addGeom (*cpmj_mjs_addGeom)
#define mjs_setString (*cpmj_mjs_setString)
#define mjs_delete (*cpmj_mjs_delete)
#endif

#endif
