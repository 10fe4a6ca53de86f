/*
 * The inner (pythonfmu) library the guard forwards to: loaded once from beside the guard
 * (inner_load_problem), and the Python thread state kept for each host thread that calls it
 * (keep_python_thread_state).  See fmi2_guard.c for the guard itself.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <string.h>

#include "guard.h"

/* ---- the inner (pythonfmu) library ---------------------------------------------- */
InnerApi inner;
static void *inner_handle = NULL;
static char inner_error[2048] = "";
static pthread_once_t inner_once = PTHREAD_ONCE_INIT;

static void load_inner(void) {
    Dl_info info;
    char path[4096];
    if (!dladdr((void *)&load_inner, &info) || info.dli_fname == NULL) {
        snprintf(inner_error, sizeof inner_error, "cannot locate the guard library itself (dladdr failed)");
        return;
    }
    const char *slash = strrchr(info.dli_fname, '/');
    size_t dir_len = slash ? (size_t)(slash - info.dli_fname) : 0;
    snprintf(path, sizeof path, "%.*s%s%s", (int)dir_len, info.dli_fname, slash ? "/" : "", AVR_INNER_LIBRARY);
    void *handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (handle == NULL) {
        snprintf(inner_error, sizeof inner_error,
                 "cannot load %s: %s. This FMU runs Python: the host process must provide libpython's "
                 "symbols (a Python host does; a C host needs LD_PRELOAD=libpython3.x.so and PYTHONHOME set to "
                 "an interpreter that has numpy)", path, dlerror());
        return;
    }
#define RESOLVE(fn)                                                                                   \
    inner.fn = (fn##TYPE *)dlsym(handle, #fn);                                                        \
    if (inner.fn == NULL) {                                                                           \
        snprintf(inner_error, sizeof inner_error, "%s lacks the symbol %s", path, #fn);               \
        return;                                                                                       \
    }
    INNER_FUNCTIONS(RESOLVE)
#undef RESOLVE
    inner_handle = handle;
}

const char *inner_load_problem(void) {
    pthread_once(&inner_once, load_inner);
    return inner_handle == NULL ? inner_error : NULL;
}

/* ---- Python thread states for threads Python did not create ----------------------------
 * pythonfmu enters Python with PyGILState_Ensure/Release around every call.  In a thread Python
 * did not create (the workers of a multi-threaded master such as libcosim, or a C host's main
 * thread) each pair creates and destroys a Python thread state, which costs more than a get or
 * set itself (measured: 7 us against 0.7 us per fmi2GetReal from a C host).  Such a thread gets
 * one thread state instead (PyGILState_Ensure once, the GIL released at once), kept until the
 * interpreter ends: a few kB per host thread.  It is not freed when the thread ends, because that
 * would need the GIL, and a host that joins its workers while holding it would deadlock. */
static struct {
    int (*is_initialized)(void);
    void *(*this_thread_state)(void);
    int (*ensure)(void);
    void *(*save_thread)(void);
} py;
static pthread_once_t py_once = PTHREAD_ONCE_INIT;
static _Thread_local int thread_state_kept = 0;

static void find_python(void) {
    *(void **)&py.is_initialized = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    *(void **)&py.this_thread_state = dlsym(RTLD_DEFAULT, "PyGILState_GetThisThreadState");
    *(void **)&py.ensure = dlsym(RTLD_DEFAULT, "PyGILState_Ensure");
    *(void **)&py.save_thread = dlsym(RTLD_DEFAULT, "PyEval_SaveThread");
}

void keep_python_thread_state(void) {
    if (thread_state_kept) return;
    pthread_once(&py_once, find_python);
    if (!py.is_initialized || !py.this_thread_state || !py.ensure || !py.save_thread || !py.is_initialized())
        return; /* no Python (yet): try again on the next call */
    thread_state_kept = 1;
    if (py.this_thread_state() != NULL) return; /* a thread Python knows */
    py.ensure();
    py.save_thread();
}
