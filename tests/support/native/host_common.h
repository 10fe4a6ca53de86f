/*
 * What every plain C test host in this folder needs, for Linux and, cross-compiled with
 * MinGW-w64, for Windows: load a library, find a symbol in it, a monotonic clock, and (after
 * fmi2Functions.h) the FMI 2.0 logger to stderr.  Each host is one translation unit that
 * includes this, so its functions are static inline (a host need not use them all).  On POSIX
 * a host defines _POSIX_C_SOURCE 200809L (dlopen, clock_gettime) before its first include.
 */
#ifndef HOST_COMMON_H
#define HOST_COMMON_H

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Lib;
static inline Lib lib_open(const char *path) { return LoadLibraryA(path); }
static inline void *lib_sym(Lib lib, const char *name) { return (void *)GetProcAddress(lib, name); }
/* Seconds of a monotonic clock. */
static inline double now_s(void) {
    LARGE_INTEGER f, t;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&t);
    return (double)t.QuadPart / (double)f.QuadPart;
}
#else
#include <dlfcn.h>
#include <time.h>
typedef void *Lib;
static inline Lib lib_open(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static inline void *lib_sym(Lib lib, const char *name) { return dlsym(lib, name); }
/* Seconds of a monotonic clock. */
static inline double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}
#endif

#include <stdarg.h>
#include <stdio.h>

#ifdef fmi2Version
/* FMI 2.0 logger: "[instance status N] message" on stderr, the variadic arguments formatted. */
static inline void host_fmi2_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                                    fmi2String message, ...) {
    (void)env, (void)category;
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%s status %d] ", name, (int)status);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}
#endif

#endif
