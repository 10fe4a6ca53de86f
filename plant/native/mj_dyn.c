/* See mj_dyn.h: on Windows, the mujoco.dll beside this library, loaded at run time. */
#if defined(_WIN32) && !defined(MJ_STATIC)
#define MJ_STATIC /* mujoco.h's declarations without dllimport: only their types are used */
#endif
#include "cassie_ctrl.h"

#include <stdio.h>

#if defined(_WIN32)
#include <windows.h>
#include <wchar.h>

#define CP_MJ_DEFINE(f) __typeof__(&f) cpmj_##f;
CP_MJ_FUNCTIONS(CP_MJ_DEFINE)

int cp_mujoco_load(char *err, int errlen) {
    static HMODULE lib = NULL;
    if (lib != NULL) return 0;
    HMODULE self = NULL;
    wchar_t path[MAX_PATH + 16];
    if (!GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCWSTR)(void *)&cp_mujoco_load, &self) ||
        GetModuleFileNameW(self, path, MAX_PATH) == 0) {
        snprintf(err, errlen, "cannot find the folder of the FMU's own library");
        return -1;
    }
    wchar_t *slash = wcsrchr(path, L'\\');
    if (slash == NULL) slash = wcsrchr(path, L'/');
    wcscpy(slash ? slash + 1 : path, L"mujoco.dll");
    HMODULE m = LoadLibraryExW(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    if (m == NULL) {
        snprintf(err, errlen, "cannot load mujoco.dll beside the FMU's library (Windows error %lu)",
                 (unsigned long)GetLastError());
        return -1;
    }
#define CP_MJ_RESOLVE(f)                                                                           \
    if ((cpmj_##f = (__typeof__(&f))(void *)GetProcAddress(m, #f)) == NULL) {                     \
        snprintf(err, errlen, "mujoco.dll has no function %s (another MuJoCo version?)", #f);     \
        return -1;                                                                                 \
    }
    CP_MJ_FUNCTIONS(CP_MJ_RESOLVE)
    lib = m;
    return 0;
}
#else
int cp_mujoco_load(char *err, int errlen) {
    (void)err, (void)errlen; /* linked at build time */
    return 0;
}
#endif
