/* Loads an FMU binary and resolves its functions the way C importers do on
 * each platform: LoadLibrary/GetProcAddress on Windows, dlopen/dlsym
 * elsewhere. Shared by importer.c and closed_loop.c, which resolve every
 * function through the official typedefs of fmi2FunctionTypes.h. */

#ifndef FMU_LIBRARY_H
#define FMU_LIBRARY_H

#include <stdio.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
typedef HMODULE fmu_library;
#else
#include <dlfcn.h>
typedef void *fmu_library;
#endif

/* Any function pointer type converts to any other in ISO C; the caller casts
 * the result to the official typedef before calling through it. */
typedef void (*fmu_function)(void);

/* NULL, with the reason on stderr, when the library cannot be loaded. */
static fmu_library fmu_library_open(const char *path) {
    fmu_library library;
#ifdef _WIN32
    library = LoadLibraryA(path);
    if (library == NULL) {
        fprintf(stderr, "LoadLibrary(%s): error %lu\n", path, (unsigned long)GetLastError());
    }
#else
    library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
    }
#endif
    return library;
}

static fmu_function fmu_library_symbol(fmu_library library, const char *name) {
#ifdef _WIN32
    /* FARPROC is a function pointer already; void (*)(void) is the type
     * that -Wcast-function-type accepts as a generic one. */
    return (fmu_function)GetProcAddress(library, name);
#else
    /* ISO C has no conversion from void * to a function pointer; POSIX
     * guarantees dlsym's result has a function pointer's representation, so
     * copying the bytes is exact. */
    void *address = dlsym(library, name);
    fmu_function function;
    memcpy(&function, &address, sizeof function);
    return function;
#endif
}

static void fmu_library_close(fmu_library library) {
#ifdef _WIN32
    FreeLibrary(library);
#else
    dlclose(library);
#endif
}

#endif
