/* gdal_loader.c: see gdal_loader.h.  One dlopen, one dlsym a function, once a process. */
#include "gdal_loader.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>

#include "log.h"

#ifndef TF_GDAL_SONAME
#define TF_GDAL_SONAME "libgdal.so"
#endif

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static tf_gdal table;
static const tf_gdal *loaded;   /* &table once every symbol resolved */
static char why_not[256];       /* otherwise: what went wrong */

/* Every symbol of TF_GDAL_FUNCTIONS from lib into table; 0, or -1 with why_not set. */
static int resolve(void *lib, const char *libname)
{
#define TF_GDAL_RESOLVE(name)                                                                    \
    if (!(*(void **)&table.name = dlsym(lib, #name))) {                                          \
        snprintf(why_not, sizeof why_not, "GDAL cannot be used: %s has no %s", libname, #name); \
        return -1;                                                                               \
    }
    TF_GDAL_FUNCTIONS(TF_GDAL_RESOLVE)
#undef TF_GDAL_RESOLVE
    return 0;
}

static void load(void)
{
    const char *env = getenv("TERRAFARM_GDAL");
    const char *libname = env && *env ? env : TF_GDAL_SONAME;
    void *lib = dlopen(libname, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        const char *e = dlerror();
        snprintf(why_not, sizeof why_not, "GDAL cannot be loaded: %s%s",
                 e ? e : libname, env && *env ? " (named by TERRAFARM_GDAL)" : "");
        return;
    }
    if (resolve(lib, libname) != 0) {
        dlclose(lib);
        return;
    }
    table.GDALAllRegister();
    loaded = &table; /* kept for the process's life: GDAL's drivers are registered in it */
}

const tf_gdal *tf_gdal_load(char *err, size_t errlen)
{
    pthread_once(&load_once, load);
    if (!loaded)
        tf_seterr(err, errlen, "%s", why_not);
    return loaded;
}
