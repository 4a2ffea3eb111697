/* backend_opencl.c: the OpenCL backend (backend_opencl.h): the C renderer's adaptive
 * antialiasing, tracing and shading as the kernels in worker/kernels (SOURCE_FILES below; see
 * worker/kernels/README.md), run on any OpenCL 1.2 device with cl_khr_fp64 (PoCL on the CPU
 * here, a vendor ICD on a GPU machine).
 *
 * Life of a backend (one per worker process, created after fork, so no OpenCL state ever
 * crosses a fork):
 *   1. tf_renderer_new computes the camera basis, sun, sky, mist and texture setup exactly as
 *      the C backend does; those values are copied into the P[] / I[] blocks of
 *      tf_cl_params.h, so the device never re-derives a scene constant.
 *   2. A device is chosen (choose_device): TERRAFARM_CL_DEVICE ("P:D" indices or a substring
 *      of the device name) or else the first GPU with fp64, else the first device with fp64.
 *   3. The kernel source is read at run time (find_kernel_dir); the program is made from the
 *      binary cache (worker/opencl_cache.h: a binary this device built before from these
 *      sources and options) or else built from source and stored there; on failure the build
 *      log goes to stderr and the error is one line.  PoCL also caches compiled programs (and
 *      the work-group functions of the first launches) in POCL_CACHE_DIR, which defaults here
 *      to a per-user cache directory (worker/pocl_cachedir.h, which also sweeps the empty files
 *      PoCL 3.1 leaves there at every start).
 *   4. The height field, all max/min grid levels (concatenated, offsets in I[]) and the texture
 *      permutation are uploaded once.
 * Each tf_cl_backend_render then runs tf_corners8 over the (w+1) x (h+1) corners (the
 * external-sample rule: the far row and column are computed here) and tf_pixels8 over the
 * pixels in batches bounded by the scratch memory of the per-pixel sample caches. */
#define CL_TARGET_OPENCL_VERSION 120
#include "worker/backend_opencl.h"
#include "clock.h"
#include "datadir.h"

#include <CL/cl.h>
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "worker/kernels/tf_cl_params.h"
#include "worker/opencl_cache.h"
#include "worker/pocl_cachedir.h"
#include "render/render_internal.h"
#include "render/sun_strips.h"
#include "log.h"

#define KERNEL_FILE "terrafarm.cl" /* the file that marks a kernel directory */
/* The program's sources, concatenated in this order.  A name with a folder is one of the C
 * renderer's own headers, shared with the kernels (common/portable.h explains how): it is found
 * beside the kernels once installed (make install copies it there), else in the checkout's
 * common/ (kernel directory/../../common/NAME). */
#define SOURCE_FILES                                                                            \
    {"tf_cl_params.h", "render/constants.h", "terrafarm.cl", "packet.cl", "common/portable.h",  \
     "terrain/noise_kernel.h", "render/sample_math.h", "render/trace_math.h",                  \
     "terrain/grid_height.h", "render/sun_math.h", "packet_trace.cl", "packet_shade.cl",       \
     "packet_render.cl"}
/* How much one work-item does, passed to the kernels as -DTF_STREAM (the batch of samples, the
 * corners per tf_corners8 item) and -DTF_PIX (pixels per tf_pixels8 item), so that host and
 * device cannot disagree; both at most 256 (the kernels name rays and pixels with a uchar).  A
 * CPU device runs few, long work-items, one SIMD job each: the most pixels an item can hold
 * give its queue the most samples to fill a batch from, and a batch of 256 samples the fewest
 * part-filled packets (default.scene 1920x1080 -j 2 on PoCL 3.1, Zen 4, 6 alternating rounds:
 * CPU 3.93 s with 128 / 64, 3.83 with 128 / 128, 3.83 with 128 / 256, 3.76-3.78 with 256 /
 * 256; 480x270 0.495 -> 0.480 s; pixels identical).  A GPU needs many work-items and little
 * private memory per item: it keeps the smaller ones (not measured here: no GPU). */
#define CPU_STREAM 256
#define CPU_PIX 256
#define GPU_STREAM 128
#define GPU_PIX 64
#define EPOCH_LIMIT 0x3fffffffu /* packet_render.cl: epochs stay below TF_STORED and TF_QUEUED */
#define MAX_SOURCE_BYTES (1 << 20)        /* a kernel file larger than this is not ours */
/* Bytes of per-pixel sample caches a batch of pixels may use.  A CPU device with one compute
 * unit (one PoCL thread: what each of render -j N's processes gets, tf_backend_share_cores)
 * gets about a core's L2: pixels write their caches sparsely, and a batch spread over 64 MB
 * left them to memory (default.scene 1920x1080 -j 2 on PoCL: 2.47-2.83 s at 64 MB, 2.33-2.54
 * at 4, 2.29-2.38 at 2, 2.28-2.46 at 1; alps 1920x640 3.19-3.41 -> 3.02-3.14 s at 2; pixels
 * identical).  Several units must share each batch's work-items, and the batch waits for its
 * slowest: small batches starve them (-j 1 with 2 threads: 2.74-2.89 s at 64 MB, 3.29-3.56 at
 * 2 a unit), so they and a GPU's thousands of lanes get large batches. */
#define SCRATCH_ONE_CPU_UNIT ((size_t)2 << 20)
#define SCRATCH_LARGE ((size_t)64 << 20)

struct tf_cl_backend {
    tf_renderer *renderer; /* the C setup the parameters are copied from */
    cl_context ctx;
    cl_command_queue queue;
    cl_program program;
    cl_kernel k_corners, k_pixels;
    cl_mem P, I, h, minmax, perm, strips; /* strips: the sun's (render/sun_strips.h) */
    float *minmax_host; /* what b->minmax reads in place (lent_to_device); freed after it */
    /* per-render buffers, grown as needed */
    cl_mem corners, corner_levels, corner_shadow, corner_records, cache, levels, have, where, out,
        pixel_shadow;
    size_t corners_cap, corner_levels_cap, corner_shadow_cap, corner_records_cap, cache_cap,
        levels_cap, have_cap, where_cap, out_cap, pixel_shadow_cap;
    cl_ulong jitter_key;
    cl_uint epoch; /* tf_pixels8's mark for the slots of the launch (packet_render.cl) */
    int lattice;
    size_t local;          /* work-group size: fixed, so PoCL specialises each kernel once */
    size_t scratch;        /* bytes of sample caches a batch of pixels may use */
    int stream, pix;       /* TF_STREAM and TF_PIX of the program (CPU_STREAM, GPU_PIX, ...) */
    char device_name[256];
    double build_seconds;  /* making the program: from the binary cache, or from source */
    enum tf_clcache_state cache_state;
    double corner_seconds, pixel_seconds; /* device time of each kernel, from profiling events */
};

/* ---------------------------------------------------------------- environment */

/* The tuning variable `name` as a whole number in [lo, hi]: 1 with *v set, 0 when unset or
 * empty; anything else is one warning naming the variable, its value and the range, and 0 (the
 * device's default stays). */
static int tuning_number(const char *name, long lo, long hi, long *v)
{
    const char *s = getenv(name);
    char *end;
    if (!s || !*s)
        return 0;
    errno = 0;
    long n = strtol(s, &end, 10);
    if (errno == 0 && *end == 0 && end != s && n >= lo && n <= hi) {
        *v = n;
        return 1;
    }
    tf_warn("%s=%s ignored: expected a whole number from %ld to %ld", name, s, lo, hi);
    return 0;
}

/* TF_STREAM and TF_PIX for the device (CPU_STREAM ... above), or TERRAFARM_CL_ITEMS=SxP for
 * tuning and the tests: S a multiple of 8 from 8 to 256, P from 1 to 256 (anything else is one
 * warning, and the device's sizes). */
static void choose_item_sizes(tf_cl_backend *b, int gpu)
{
    b->stream = gpu ? GPU_STREAM : CPU_STREAM;
    b->pix = gpu ? GPU_PIX : CPU_PIX;
    const char *items = getenv("TERRAFARM_CL_ITEMS");
    int stream, pix;
    char end;
    if (!items || !*items)
        return;
    if (sscanf(items, "%dx%d%c", &stream, &pix, &end) == 2 && stream >= 8 && stream <= 256 &&
        stream % 8 == 0 && pix >= 1 && pix <= 256) {
        b->stream = stream;
        b->pix = pix;
    } else {
        tf_warn("TERRAFARM_CL_ITEMS=%s ignored: expected SxP, S a multiple of 8 from 8 to 256 "
                "(samples a batch) and P from 1 to 256 (pixels a work-item)", items);
    }
}

/* PoCL's cache directory when terrafarm chose it (empty: the user's, or none), set once by
 * tf_cl_prepare_environment before any thread opens a device. */
static char pocl_dir[PATH_MAX];

/* See backend_opencl.h. */
void tf_cl_prepare_environment(void)
{
    static int done; /* once a process: the first call is made before any thread opens a device */
    if (done)
        return;
    done = 1;
    tf_pocl_cache_dir_choose(pocl_dir, sizeof pocl_dir);
    if (!pocl_dir[0])
        return;
    int removed = tf_pocl_cache_sweep(pocl_dir, time(NULL), TF_POCL_TEMPFILE_MAX_AGE_S);
    if (removed > 0)
        tf_debug("PoCL cache %s: removed %d temporary files PoCL left behind", pocl_dir, removed);
}

/* After a new entry was stored (a new source, options, driver or device): the entries and
 * PoCL's programs nobody has used for TF_CLCACHE_MAX_IDLE_S go. */
static void prune_caches(const tf_clcache *c)
{
    const time_t now = time(NULL);
    int entries = tf_clcache_prune(c, now, TF_CLCACHE_MAX_IDLE_S);
    int programs = pocl_dir[0] ? tf_pocl_cache_prune(pocl_dir, now, TF_CLCACHE_MAX_IDLE_S) : 0;
    if (entries > 0 || programs > 0)
        tf_debug("OpenCL caches: removed %d program entries and %d PoCL program directories "
                 "unused for %ld days", entries > 0 ? entries : 0, programs > 0 ? programs : 0,
                 TF_CLCACHE_MAX_IDLE_S / 86400);
}

/* Read a whole file of at most MAX_SOURCE_BYTES.  NULL if absent, unreadable or too big. */
static char *read_text(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    char *buf = malloc(MAX_SOURCE_BYTES + 1);
    size_t n = buf ? fread(buf, 1, MAX_SOURCE_BYTES + 1, f) : 0;
    int bad = !buf || ferror(f) || n > MAX_SOURCE_BYTES;
    fclose(f);
    if (bad) {
        free(buf);
        return NULL;
    }
    buf[n] = 0;
    *len = n;
    return buf;
}

/* The kernel directory, in order: $TERRAFARM_KERNELS (an explicit choice wins), next to the
 * executable (bin/../worker/kernels, and build/tests/../../worker/kernels for test programs),
 * the installed copies, then ./worker/kernels.  0, or -1 with a message listing the search. */
static int find_kernel_dir(char *dir, size_t len, char *err, size_t errlen)
{
    static const char *const beside[] = {"/../worker/kernels", "/../../worker/kernels",
                                         "/../share/terrafarm/kernels", NULL};
    static const char *const fixed[] = {"/usr/local/share/terrafarm/kernels",
                                        "/usr/share/terrafarm/kernels", "worker/kernels", NULL};
    int rc = tf_datadir_find("TERRAFARM_KERNELS", beside, fixed, KERNEL_FILE, dir, len);
    if (rc == 0)
        return 0;
    if (rc == -2)
        return tf_seterr(err, errlen, "TERRAFARM_KERNELS=%s has no " KERNEL_FILE, dir);
    snprintf(err, errlen,
             "OpenCL kernels not found (looked in $TERRAFARM_KERNELS, <exe>/../worker/kernels, "
             "/usr/local/share/terrafarm/kernels, ./worker/kernels)");
    return -1;
}

/* ---------------------------------------------------------------- device choice */

static int device_has_fp64(cl_device_id d)
{
    char ext[8192] = "";
    clGetDeviceInfo(d, CL_DEVICE_EXTENSIONS, sizeof ext - 1, ext, NULL);
    return strstr(ext, "cl_khr_fp64") != NULL;
}

static int contains_ci(const char *hay, const char *needle)
{
    size_t n = strlen(needle);
    for (; *hay; hay++) {
        size_t i = 0;
        while (i < n && hay[i] && tolower((unsigned char)hay[i]) == tolower((unsigned char)needle[i]))
            i++;
        if (i == n)
            return 1;
    }
    return n == 0;
}

#define MAX_PLATFORMS 16
#define MAX_DEVICES 32

/* The device TERRAFARM_CL_DEVICE asks for: "P:D" (platform and device indices), or a part of
 * its name; text NULL when unset. */
typedef struct device_wish {
    const char *text;
    int p, d; /* -1: by name */
} device_wish;

static device_wish wish_from_env(void)
{
    device_wish w = {getenv("TERRAFARM_CL_DEVICE"), -1, -1};
    char tail;
    if (w.text && !*w.text)
        w.text = NULL;
    if (w.text && sscanf(w.text, "%d:%d%c", &w.p, &w.d, &tail) != 2)
        w.p = w.d = -1;
    return w;
}

static int wished(const device_wish *w, cl_uint p, cl_uint d, const char *dname)
{
    return w->p >= 0 ? (int)p == w->p && (int)d == w->d : contains_ci(dname, w->text);
}

/* 2: a GPU with double precision, 1: another device with it, 0: none. */
static int device_rank(cl_device_id dev)
{
    if (!device_has_fp64(dev))
        return 0;
    cl_device_type type = 0;
    clGetDeviceInfo(dev, CL_DEVICE_TYPE, sizeof type, &type, NULL);
    return (type & CL_DEVICE_TYPE_GPU) ? 2 : 1;
}

/* The device the user named, if it has double precision.  0, or -1 with a message. */
static int take_wished(cl_device_id dev, const char *dname, const device_wish *w,
                       cl_device_id *out, char *name, size_t namelen, char *err, size_t errlen)
{
    if (!device_has_fp64(dev))
        return tf_seterr(err, errlen, "OpenCL device '%s' (TERRAFARM_CL_DEVICE=%s) lacks double "
                         "precision (cl_khr_fp64)", dname, w->text);
    *out = dev;
    snprintf(name, namelen, "%s", dname);
    return 0;
}

/* Platform plat's devices into devs (at most MAX_DEVICES): how many. */
static cl_uint platform_devices(cl_platform_id plat, cl_device_id *devs)
{
    cl_uint nd = 0;
    if (clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, MAX_DEVICES, devs, &nd) != CL_SUCCESS)
        return 0;
    return nd > MAX_DEVICES ? MAX_DEVICES : nd;
}

/* Choose the device (see the top of the file).  0, or -1 with a message. */
static int choose_device(cl_device_id *out, char *name, size_t namelen, char *err, size_t errlen)
{
    cl_platform_id plats[MAX_PLATFORMS];
    cl_uint np = 0;
    if (clGetPlatformIDs(MAX_PLATFORMS, plats, &np) != CL_SUCCESS || np == 0)
        return tf_seterr(err, errlen, "no OpenCL platform found (install an OpenCL ICD, e.g. "
                                      "pocl-opencl-icd, or use --backend c)");
    if (np > MAX_PLATFORMS)
        np = MAX_PLATFORMS;
    const device_wish w = wish_from_env();
    cl_device_id best = NULL;
    int best_rank = 0;
    for (cl_uint p = 0; p < np; p++) {
        cl_device_id devs[MAX_DEVICES];
        cl_uint nd = platform_devices(plats[p], devs);
        for (cl_uint d = 0; d < nd; d++) {
            char dname[256] = "";
            clGetDeviceInfo(devs[d], CL_DEVICE_NAME, sizeof dname - 1, dname, NULL);
            if (w.text) {
                if (wished(&w, p, d, dname))
                    return take_wished(devs[d], dname, &w, out, name, namelen, err, errlen);
                continue;
            }
            int rank = device_rank(devs[d]);
            if (rank > best_rank) {
                best_rank = rank;
                best = devs[d];
                snprintf(name, namelen, "%s", dname);
            }
        }
    }
    if (w.text)
        return tf_seterr(err, errlen, "TERRAFARM_CL_DEVICE=%s matches no OpenCL device", w.text);
    if (!best)
        return tf_seterr(err, errlen, "no OpenCL device with double precision (cl_khr_fp64)");
    *out = best;
    return 0;
}

/* ---------------------------------------------------------------- program */

/* Read source `name` of SOURCE_FILES for kernel directory dir: a plain name from dir; a shared
 * header ("render/constants.h", "common/portable.h") from dir by its base name (installed),
 * else from the checkout's common/ beside dir.  NULL if none is readable; *where gets the path
 * last tried. */
static char *read_source(const char *dir, const char *name, size_t *len, char *where,
                         size_t wherelen)
{
    const char *slash = strrchr(name, '/');
    snprintf(where, wherelen, "%s/%s", dir, slash ? slash + 1 : name);
    char *src = read_text(where, len);
    if (src || !slash)
        return src;
    const char *under_common = strncmp(name, "common/", 7) == 0 ? name + 7 : name;
    snprintf(where, wherelen, "%s/../../common/%s", dir, under_common);
    return read_text(where, len);
}

static const char *const source_names[] = SOURCE_FILES;
enum { NSRC = sizeof source_names / sizeof source_names[0] };

/* Read every file of SOURCE_FILES for kernel directory dir into src[] and len[].  0, or -1 with
 * a message naming the first file missing (nothing left allocated). */
static int read_sources(const char *dir, char **src, size_t *len, char *err, size_t errlen)
{
    const char *const *names = source_names;
    char path[PATH_MAX + 64], missing_path[PATH_MAX + 64] = "";
    int missing = -1;
    for (int i = 0; i < NSRC; i++) {
        src[i] = read_source(dir, names[i], &len[i], path, sizeof path);
        if (!src[i] && missing < 0) {
            missing = i;
            snprintf(missing_path, sizeof missing_path, "%s", path);
        }
    }
    if (missing < 0)
        return 0;
    for (int i = 0; i < NSRC; i++)
        free(src[i]);
    if (strchr(names[missing], '/'))
        return tf_seterr(err, errlen,
                         "cannot read the shared OpenCL kernel header %s (looked beside the "
                         "kernels in %s, then in the checkout at %s)",
                         names[missing], dir, missing_path);
    return tf_seterr(err, errlen, "cannot read the OpenCL kernel source %s", missing_path);
}

/* A failed build's log, to stderr (it is many lines; the error itself stays one line). */
static void print_build_log(cl_program program, cl_device_id dev, const char *dir)
{
    size_t loglen = 0;
    clGetProgramBuildInfo(program, dev, CL_PROGRAM_BUILD_LOG, 0, NULL, &loglen);
    if (loglen == 0 || loglen >= ((size_t)16 << 20))
        return;
    char *log = malloc(loglen + 1);
    if (log && clGetProgramBuildInfo(program, dev, CL_PROGRAM_BUILD_LOG, loglen, log, NULL) ==
                   CL_SUCCESS) {
        log[loglen] = 0;
        fprintf(stderr, "--- OpenCL build log (%s) ---\n%s\n---\n", dir, log);
    }
    free(log);
}

/* The program built from the sources.  NULL with a message (and the build log on stderr). */
static cl_program program_from_source(cl_context ctx, cl_device_id dev, char **src,
                                      const size_t *len, const char *options, const char *dir,
                                      char *err, size_t errlen)
{
    cl_int rc;
    cl_program p = clCreateProgramWithSource(ctx, NSRC, (const char **)src, len, &rc);
    if (rc != CL_SUCCESS) {
        tf_seterr(err, errlen, "OpenCL: cannot create the program (error %d)", rc);
        return NULL;
    }
    rc = clBuildProgram(p, 1, &dev, options, NULL, NULL);
    if (rc == CL_SUCCESS)
        return p;
    print_build_log(p, dev, dir);
    clReleaseProgram(p);
    tf_seterr(err, errlen, "OpenCL: building the kernels in %s failed (error %d; build log "
              "above)", dir, rc);
    return NULL;
}

/* The program from the binary cache (worker/opencl_cache.h) if it holds a good entry, else built
 * from the sources and stored there.  A refused directory or entry is one warning. */
static cl_program cached_program(tf_cl_backend *b, cl_device_id dev, char **src,
                                 const size_t *len, const char *options, const char *dir,
                                 char *err, size_t errlen)
{
    tf_clcache c;
    char why[PATH_MAX + 256];
    double t0 = tf_now_s();
    if (tf_clcache_open(&c, dev, NSRC, (const char *const *)src, len, options, why,
                        sizeof why) && c.state == TF_CLCACHE_REFUSED)
        tf_warn("OpenCL program cache not used: %s; building from source", why);
    cl_program p = tf_clcache_load(&c, b->ctx, dev, options, why, sizeof why);
    if (p)
        c.state = TF_CLCACHE_HIT;
    else if (why[0]) {
        tf_warn("OpenCL program cache: %s/%s refused (%s); rebuilding it", c.dir, c.name, why);
        c.state = TF_CLCACHE_REBUILT;
    }
    if (!p && (p = program_from_source(b->ctx, dev, src, len, options, dir, err, errlen)) &&
        c.dirfd >= 0) {
        if (tf_clcache_store(&c, p, why, sizeof why))
            tf_warn("OpenCL program cache: %s", why);
        else
            prune_caches(&c);
    }
    if (p)
        tf_debug("OpenCL program cache %s: %s/%s (program ready in %.3f s)",
                 tf_clcache_state_name(c.state), c.dir, c.name, tf_now_s() - t0);
    b->cache_state = c.state;
    tf_clcache_close(&c);
    return p;
}

/* Make the program from SOURCE_FILES, concatenated in that order (through the binary cache),
 * and its two kernels. */
static int build_program(tf_cl_backend *b, cl_device_id dev, char *err, size_t errlen)
{
    char dir[PATH_MAX];
    size_t len[NSRC];
    char *src[NSRC];
    if (find_kernel_dir(dir, sizeof dir, err, errlen) || read_sources(dir, src, len, err, errlen))
        return -1;
    char options[128];
    snprintf(options, sizeof options, "-cl-std=CL1.2 -DTF_STREAM=%d -DTF_PIX=%d", b->stream,
             b->pix);
    double t0 = tf_now_s();
    b->program = cached_program(b, dev, src, len, options, dir, err, errlen);
    b->build_seconds = tf_now_s() - t0;
    for (int i = 0; i < NSRC; i++)
        free(src[i]);
    if (!b->program)
        return -1;
    cl_int rc;
    b->k_corners = clCreateKernel(b->program, "tf_corners8", &rc);
    if (rc == CL_SUCCESS)
        b->k_pixels = clCreateKernel(b->program, "tf_pixels8", &rc);
    if (rc != CL_SUCCESS) {
        tf_seterr(err, errlen, "OpenCL: kernel missing from the sources in %s (error %d)", dir,
                 rc);
        return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------- parameters and uploads */

static void put3(double *P, int k, tf_vec3 v)
{
    P[k] = v.x;
    P[k + 1] = v.y;
    P[k + 2] = v.z;
}

/* The sun's strips' frame (no strips: strips 0, which proves nothing). */
static void fill_sun_frame(const tf_sun_strips *st, double *P, int *I)
{
    if (!st)
        return;
    const tf_sun_frame *f = &st->frame;
    const double v[TF_CL_SUN_DOUBLES] = {
        f->a_s,    f->b_s,  f->a_p,        f->b_p,  f->along0, f->across0, f->inv_w, f->inv_ds,
        f->ds,     f->climb, f->t_per_cell, f->eps, f->dx,     f->dy,      f->cell};
    for (int i = 0; i < TF_CL_SUN_DOUBLES; i++)
        P[TFP_SUN_FRAME + i] = v[i];
    I[TFI_SUN_STRIPS] = f->strips;
    I[TFI_SUN_BINS] = f->bins;
    I[TFI_SUN_LOOK] = f->look;
    I[TFI_SUN_N] = f->n;
}

/* The height field's scalars. */
static void terrain_params(const tf_heightfield *hf, double *P, int *I)
{
    P[TFP_CELL] = hf->cell;
    P[TFP_EXTENT] = hf->extent;
    P[TFP_HMIN] = hf->hmin;
    P[TFP_HMAX] = hf->hmax;
    /* trace.c's vouched asks a finite bound; NAN makes every kernel vouch fail */
    P[TFP_SLOPE_MAX] = hf->slope_max >= 0 && hf->slope_max < INFINITY ? hf->slope_max : NAN;
    I[TFI_N] = hf->n;
    I[TFI_CELLS] = hf->cells;
    I[TFI_LEVELS] = hf->levels;
}

/* The camera: its frame, and a panorama's. */
static void camera_params(const tf_camera *cam, double *P, int *I)
{
    put3(P, TFP_CAM_POS, cam->position);
    put3(P, TFP_CAM_FORWARD, cam->forward);
    put3(P, TFP_CAM_RIGHT, cam->right);
    put3(P, TFP_CAM_UP, cam->up);
    P[TFP_HALF_W] = cam->half_w;
    P[TFP_HALF_H] = cam->half_h;
    put3(P, TFP_PANO_FORWARD, cam->pano_forward);
    put3(P, TFP_PANO_RIGHT, cam->pano_right);
    put3(P, TFP_PANO_UP, cam->pano_up);
    P[TFP_SWEEP] = cam->sweep;
    P[TFP_V_CENTRE] = cam->v_centre;
    P[TFP_V_HALF] = cam->v_half;
    I[TFI_WIDTH] = cam->width;
    I[TFI_HEIGHT] = cam->height;
    I[TFI_CAM_KIND] = cam->kind == TF_CAMERA_PANORAMA;
}

/* The shader's derived values, with its own octave weights and snow bounds (shade.h). */
static void shader_params(const tf_shader *sh, double *P, int *I)
{
    put3(P, TFP_SUN_DIR, sh->sun_dir);
    put3(P, TFP_SUN_LIGHT, sh->sun_light);
    put3(P, TFP_SKY_LIGHT, sh->sky_light);
    P[TFP_MIST_K] = sh->mist_k;
    P[TFP_BAND] = sh->band;
    P[TFP_BUMP_SCALE] = sh->bump_scale;
    P[TFP_RIPPLE_SCALE] = sh->ripple_scale;
    P[TFP_SHADOW_LIFT] = sh->shadow_lift;
    P[TFP_PIXEL_ANGLE] = sh->pixel_angle;
    tf_shade_octave_weights(TF_BUMP_H, P + TFP_AMP_H08, TF_CL_AMP_TABLE);
    tf_shade_octave_weights(TF_SNOW_H, P + TFP_AMP_H05, TF_CL_AMP_TABLE); /* = TF_RIPPLE_H */
    _Static_assert(TF_CL_SNOW_TERMS == (int)TF_SNOW_OCTAVES, "the kernels' snow octaves");
    tf_shade_snow_rest_bounds(P + TFP_SNOW_REST, TF_CL_SNOW_TERMS);
    I[TFI_TEXTURED] = sh->textured;
    I[TFI_SMOOTH] = sh->smooth;
}

/* The scene's materials, mist and sky as written. */
static void scene_params(const tf_scene *s, double *P, int *I)
{
    P[TFP_SEA_LEVEL] = s->materials.sea_level;
    P[TFP_TREE_LINE] = s->materials.tree_line;
    P[TFP_SNOW_LINE] = s->materials.snow_line;
    P[TFP_SNOW_JITTER] = s->materials.snow_jitter;
    P[TFP_ROCK_SLOPE] = s->materials.rock_slope_deg;
    P[TFP_BUMP] = s->materials.bump;
    P[TFP_MIST_DENSITY] = s->mist.density;
    put3(P, TFP_MIST_COLOR, s->mist.color);
    put3(P, TFP_MIST_EXT, s->mist.extinction);
    put3(P, TFP_SKY_HORIZON, s->sky.horizon);
    put3(P, TFP_SKY_ZENITH, s->sky.zenith);
    I[TFI_MIST_ENABLED] = s->mist.enabled;
    I[TFI_MIST_HOMOG] = s->mist.homogeneous;
}

/* Copy what tf_renderer_new derived into the P[] / I[] blocks. */
static void fill_params(const tf_renderer *r, double *P, int *I)
{
    terrain_params(r->hf, P, I);
    camera_params(&r->camera, P, I);
    shader_params(&r->shader, P, I);
    scene_params(r->scene, P, I);
    P[TFP_THRESHOLD] = r->threshold;
    I[TFI_LATTICE] = r->lattice;
    I[TFI_DEPTH] = r->depth;
    fill_sun_frame(r->sun_strips, P, I);
}

static cl_mem upload(tf_cl_backend *b, const void *data, size_t bytes, cl_int *rc)
{
    return clCreateBuffer(b->ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes, (void *)data,
                          rc);
}

/* The sun's strips' table of renderer r, or two unread floats where it has none. */
static cl_mem upload_strips(tf_cl_backend *b, const tf_renderer *r, cl_int *rc)
{
    static const float none[2] = {0, 0};
    const tf_sun_strips *st = r->sun_strips;
    if (!st)
        return upload(b, none, sizeof none, rc);
    return upload(b, st->table, tf_sun_strips_table_bytes(st), rc);
}

/* A read-only buffer over host memory that outlives it and never changes (the height field, the
 * max/min grids).  A CPU device reads it in place: a forked worker shares the coordinator's
 * pages instead of copying tens of MB into fresh ones (default.scene 1920x1080 -j 2: ~19 000
 * page faults a render, against ~4 000 for the C backend); a GPU copies it as it would. */
static cl_mem lent_to_device(tf_cl_backend *b, const void *data, size_t bytes, cl_int *rc)
{
    return clCreateBuffer(b->ctx, CL_MEM_READ_ONLY | CL_MEM_USE_HOST_PTR, bytes, (void *)data,
                          rc);
}

/* The max/min grid levels' offsets into I[]; their total size, or 0 if it does not fit an int. */
static size_t level_offsets(const tf_heightfield *hf, int *I)
{
    size_t total = 0;
    for (int L = 0; L < hf->levels; L++) {
        size_t side = (size_t)(hf->cells >> L);
        if (total > (size_t)INT_MAX - side * side)
            return 0;
        I[TFI_LEVEL_OFFSET + L] = (int)total;
        total += side * side;
    }
    return total;
}

/* Upload the parameters, heights, the max/min mipmap (levels concatenated, each cell's max and
 * min side by side) and the noise permutation.  The grid level offsets go into I[] before I is uploaded. */
static int upload_world(tf_cl_backend *b, char *err, size_t errlen)
{
    const tf_heightfield *hf = b->renderer->hf;
    double P[TFP_COUNT] = {0};
    int I[TFI_COUNT] = {0};
    if (hf->levels > TF_CL_MAX_LEVELS) {
        tf_seterr(err, errlen, "OpenCL: height field with %d grid levels (at most %d)", hf->levels,
                 TF_CL_MAX_LEVELS);
        return -1;
    }
    fill_params(b->renderer, P, I);
    size_t total = level_offsets(hf, I);
    if (total == 0) {
        tf_seterr(err, errlen, "OpenCL: height field too large for the grid offsets");
        return -1;
    }
    /* (max, min) interleaved: the walk reads both of a cell at once (packet_trace.cl) */
    float *mm = total <= SIZE_MAX / (2 * sizeof *mm) ? malloc(total * 2 * sizeof *mm) : NULL;
    if (!mm) {
        tf_seterr(err, errlen, "OpenCL: out of memory for the max grids");
        return -1;
    }
    for (int L = 0; L < hf->levels; L++) {
        size_t side = (size_t)(hf->cells >> L), at = (size_t)I[TFI_LEVEL_OFFSET + L];
        for (size_t k = 0; k < side * side; k++) {
            mm[2 * (at + k)] = hf->maxgrid[L][k];
            mm[2 * (at + k) + 1] = hf->mingrid[L][k];
        }
    }
    cl_int rc[6];
    b->P = upload(b, P, sizeof P, &rc[0]);
    b->I = upload(b, I, sizeof I, &rc[1]);
    b->h = lent_to_device(b, hf->h, (size_t)hf->n * (size_t)hf->n * sizeof(float), &rc[2]);
    b->minmax_host = mm;
    b->minmax = lent_to_device(b, mm, total * 2 * sizeof *mm, &rc[3]);
    b->perm = upload(b, b->renderer->shader.noise.perm, sizeof b->renderer->shader.noise.perm,
                     &rc[4]);
    b->strips = upload_strips(b, b->renderer, &rc[5]);
    for (int i = 0; i < 6; i++)
        if (rc[i] != CL_SUCCESS) {
            tf_seterr(err, errlen, "OpenCL: cannot upload the height field (error %d)", rc[i]);
            return -1;
        }
    return 0;
}

/* ---------------------------------------------------------------- public */

const char *tf_cl_terrain_unsupported(int procedural, int eroded)
{
    if (procedural)
        return "the OpenCL backend cannot trace procedural terrain ([terrain] procedural = yes)";
    if (eroded)
        return "the OpenCL backend cannot shade an eroded terrain's water and silt ([erosion])";
    return NULL;
}

const char *tf_cl_scene_unsupported(const tf_scene *s)
{
    return tf_cl_terrain_unsupported(s->terrain.procedural, s->terrain.erosion.fluvial_steps > 0);
}

/* The height field the backend was given, refused in one line if the kernels cannot render it
 * (-1), else 0. */
static int refuse_unsupported(const tf_heightfield *hf, char *err, size_t errlen)
{
    const char *why = tf_cl_terrain_unsupported(hf->proc != NULL, hf->silt != NULL);
    return why ? tf_seterr(err, errlen, "%s; use --backend c", why) : 0;
}

/* The device's sizes: work-group, sample-cache scratch, items (see the comments inside). */
static void choose_sizes(tf_cl_backend *b, cl_device_id dev)
{
    /* Work-group size.  On a CPU a work-item is already a long, SIMD job (a batch of up to 256
     * samples), and a task has only a few dozen of them: groups of one let PoCL's threads
     * share a task's items evenly (bench_opencl default.scene 960x540, stamps: 1.28x C with
     * groups of 1, 1.10x with 8).  On a GPU, a conventional 32. */
    cl_device_type type = 0;
    clGetDeviceInfo(dev, CL_DEVICE_TYPE, sizeof type, &type, NULL);
    long local, scratch;
    b->local = tuning_number("TERRAFARM_CL_LOCAL", 1, 1024, &local) ? (size_t)local
               : (type & CL_DEVICE_TYPE_GPU)                          ? 32
                                                                      : 1;
    cl_uint units = 1;
    clGetDeviceInfo(dev, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof units, &units, NULL);
    /* bytes; for tuning and the tests */
    b->scratch = tuning_number("TERRAFARM_CL_SCRATCH", 1, LONG_MAX, &scratch) ? (size_t)scratch
                 : (type & CL_DEVICE_TYPE_CPU) && units == 1 ? SCRATCH_ONE_CPU_UNIT
                                                             : SCRATCH_LARGE;
    choose_item_sizes(b, (type & CL_DEVICE_TYPE_GPU) != 0);
}

tf_cl_backend *tf_cl_backend_open(char *err, size_t errlen)
{
    tf_cl_backend *b = calloc(1, sizeof *b);
    if (!b) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    tf_cl_prepare_environment();
    cl_device_id dev;
    cl_int rc;
    if (choose_device(&dev, b->device_name, sizeof b->device_name, err, errlen))
        goto fail;
    choose_sizes(b, dev);
    tf_debug("OpenCL device: %s", b->device_name);
    b->ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, &rc);
    if (rc != CL_SUCCESS) {
        tf_seterr(err, errlen, "OpenCL: cannot create a context on '%s' (error %d)",
                 b->device_name, rc);
        goto fail;
    }
    b->queue = clCreateCommandQueue(b->ctx, dev, CL_QUEUE_PROFILING_ENABLE, &rc);
    if (rc != CL_SUCCESS) {
        tf_seterr(err, errlen, "OpenCL: cannot create a queue on '%s' (error %d)", b->device_name,
                 rc);
        goto fail;
    }
    if (build_program(b, dev, err, errlen))
        goto fail;
    return b;
fail:
    tf_cl_backend_free(b);
    return NULL;
}

int tf_cl_backend_attach(tf_cl_backend *b, const tf_scene *s, const tf_heightfield *hf, char *err,
                         size_t errlen)
{
    if (refuse_unsupported(hf, err, errlen))
        return -1;
    if (b->renderer)
        return tf_seterr(err, errlen, "OpenCL: the backend already renders a scene");
    b->renderer = tf_renderer_new(s, hf, err, errlen);
    if (!b->renderer)
        return -1;
    b->jitter_key = b->renderer->jitter_key;
    b->lattice = b->renderer->lattice;
    return upload_world(b, err, errlen);
}

tf_cl_backend *tf_cl_backend_new(const tf_scene *s, const tf_heightfield *hf, char *err,
                                 size_t errlen)
{
    if (refuse_unsupported(hf, err, errlen)) /* before the device's start, which costs 0.1 s */
        return NULL;
    tf_cl_backend *b = tf_cl_backend_open(err, errlen);
    if (b && tf_cl_backend_attach(b, s, hf, err, errlen)) {
        tf_cl_backend_free(b);
        return NULL;
    }
    return b;
}

int tf_cl_backend_set_scene(tf_cl_backend *b, const tf_scene *s, char *err, size_t errlen)
{
    if (!b->renderer)
        return tf_seterr(err, errlen, "OpenCL: no scene attached to the backend");
    const tf_heightfield *hf = b->renderer->hf;
    tf_renderer *r = tf_renderer_new(s, hf, err, errlen);
    if (!r)
        return -1;
    if (r->jitter_key != b->jitter_key || r->lattice != b->lattice) {
        tf_renderer_free(r);
        return tf_seterr(err, errlen, "OpenCL: the new scene differs in more than its camera and sun");
    }
    double P[TFP_COUNT] = {0};
    int I[TFI_COUNT] = {0};
    fill_params(r, P, I);
    level_offsets(hf, I); /* fitted when the backend was made */
    /* the queue is in order: the writes land after every kernel already enqueued */
    cl_int rc = clEnqueueWriteBuffer(b->queue, b->P, CL_TRUE, 0, sizeof P, P, 0, NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clEnqueueWriteBuffer(b->queue, b->I, CL_TRUE, 0, sizeof I, I, 0, NULL, NULL);
    /* the sun may have moved: the new strips (kernels already queued keep the old buffer) */
    cl_mem strips = rc == CL_SUCCESS ? upload_strips(b, r, &rc) : NULL;
    if (rc != CL_SUCCESS) {
        tf_renderer_free(r);
        return tf_seterr(err, errlen, "OpenCL: cannot upload the new camera (error %d)", rc);
    }
    clReleaseMemObject(b->strips);
    b->strips = strips;
    tf_renderer_free(b->renderer);
    b->renderer = r;
    return 0;
}

const char *tf_cl_backend_device(const tf_cl_backend *b) { return b->device_name; }
double tf_cl_backend_build_seconds(const tf_cl_backend *b) { return b->build_seconds; }
const char *tf_cl_backend_cache(const tf_cl_backend *b)
{
    return tf_clcache_state_name(b->cache_state);
}

void tf_cl_backend_kernel_seconds(const tf_cl_backend *b, double *corners, double *pixels)
{
    *corners = b->corner_seconds;
    *pixels = b->pixel_seconds;
}

/* Add the device time of a finished kernel's event to *acc, and release the event.  Returns
 * the kernel's execution status: CL_COMPLETE, or the negative error it ended with (a queue
 * that finished does not say whether its commands succeeded). */
static cl_int account(cl_event ev, double *acc)
{
    cl_int status = CL_INVALID_EVENT;
    if (clGetEventInfo(ev, CL_EVENT_COMMAND_EXECUTION_STATUS, sizeof status, &status, NULL) !=
        CL_SUCCESS)
        status = CL_INVALID_EVENT;
    cl_ulong start = 0, end = 0;
    if (clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof start, &start, NULL) ==
            CL_SUCCESS &&
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof end, &end, NULL) ==
            CL_SUCCESS &&
        end >= start)
        *acc += 1e-9 * (double)(end - start);
    clReleaseEvent(ev);
    return status;
}

/* A kernel's execution status (account) into *rc, unless *rc already holds an error. */
static void keep_first_error(cl_int *rc, cl_int status)
{
    if (*rc == CL_SUCCESS && status != CL_COMPLETE)
        *rc = status < 0 ? status : CL_INVALID_EVENT;
}

/* Make *buf hold at least `bytes` (read-write, device-side), growing it in place. */
static int ensure(tf_cl_backend *b, cl_mem *buf, size_t *cap, size_t bytes)
{
    if (*buf && *cap >= bytes)
        return 0;
    if (*buf)
        clReleaseMemObject(*buf);
    cl_int rc;
    *buf = clCreateBuffer(b->ctx, CL_MEM_READ_WRITE, bytes, NULL, &rc);
    *cap = rc == CL_SUCCESS ? bytes : 0;
    return rc == CL_SUCCESS ? 0 : -1;
}

/* Zero the slot states of the sample caches (a state no epoch equals) and restart the epochs. */
static cl_int reset_have(tf_cl_backend *b)
{
    cl_uint zero = 0;
    b->epoch = 0;
    return clEnqueueFillBuffer(b->queue, b->have, &zero, sizeof zero, 0, b->have_cap, 0, NULL,
                               NULL);
}

/* The slot states: reset whenever (re)allocated. */
static int ensure_have(tf_cl_backend *b, size_t slots)
{
    if (b->have && b->have_cap >= slots * sizeof(cl_uint))
        return 0;
    if (ensure(b, &b->have, &b->have_cap, slots * sizeof(cl_uint)))
        return -1;
    return reset_have(b) == CL_SUCCESS ? 0 : -1;
}

/* A new epoch for the next tf_pixels8 launch; after 2^30 - 1 launches the slot states are
 * reset so an old mark can never pass for a new one. */
static cl_int next_epoch(tf_cl_backend *b)
{
    if (b->epoch + 1 >= EPOCH_LIMIT) {
        cl_int rc = reset_have(b);
        if (rc != CL_SUCCESS)
            return rc;
    }
    b->epoch++;
    return CL_SUCCESS;
}

/* n rounded up to a multiple of the work-group size (kernels ignore the surplus items). */
static size_t round_up(size_t n, size_t local) { return (n + local - 1) / local * local; }

/* The world's arguments every kernel starts with (make_world's), in their order. */
static cl_int set_world_args(tf_cl_backend *b, cl_kernel k)
{
    cl_int rc = clSetKernelArg(k, 0, sizeof(cl_mem), &b->P);
    rc |= clSetKernelArg(k, 1, sizeof(cl_mem), &b->I);
    rc |= clSetKernelArg(k, 2, sizeof(cl_ulong), &b->jitter_key);
    rc |= clSetKernelArg(k, 3, sizeof(cl_mem), &b->h);
    rc |= clSetKernelArg(k, 4, sizeof(cl_mem), &b->minmax);
    rc |= clSetKernelArg(k, 5, sizeof(cl_mem), &b->perm);
    rc |= clSetKernelArg(k, 6, sizeof(cl_mem), &b->strips);
    return rc;
}

/* The arguments both rendering kernels share, in the order they take them. */
static cl_int set_common_args(tf_cl_backend *b, cl_kernel k, tf_rect rect)
{
    cl_int rc = set_world_args(b, k);
    rc |= clSetKernelArg(k, 7, sizeof(cl_int), &rect.x);
    rc |= clSetKernelArg(k, 8, sizeof(cl_int), &rect.y);
    return rc;
}

static uint64_t sum_u32(const cl_uint *v, size_t n)
{
    uint64_t s = 0;
    for (size_t i = 0; i < n; i++)
        s += v[i];
    return s;
}

/* Queue tf_pixels8 over the batch of pixels from `first` (of npixels, at most `batch` of them).
 * The kernel's arguments are captured at the enqueue, so the next batch may set its own while
 * this one waits in the in-order queue; no batch is waited for here (a wait per batch put the
 * host thread and PoCL's thread through a lock and a wake-up each, and left the device idle
 * until the host had queued the next). */
static cl_int enqueue_pixel_batch(tf_cl_backend *b, tf_rect rect, size_t first, size_t npixels,
                                  size_t batch, cl_event *ev)
{
    cl_int rw = rect.w, rh = rect.h, f = (cl_int)first;
    cl_int count = (cl_int)(npixels - first < batch ? npixels - first : batch);
    cl_int rc = set_common_args(b, b->k_pixels, rect);
    rc |= clSetKernelArg(b->k_pixels, 9, sizeof rw, &rw);
    rc |= clSetKernelArg(b->k_pixels, 10, sizeof f, &f);
    rc |= clSetKernelArg(b->k_pixels, 11, sizeof count, &count);
    rc |= clSetKernelArg(b->k_pixels, 12, sizeof(cl_mem), &b->corners);
    rc |= clSetKernelArg(b->k_pixels, 13, sizeof(cl_mem), &b->corner_levels);
    rc |= clSetKernelArg(b->k_pixels, 14, sizeof(cl_mem), &b->cache);
    rc |= clSetKernelArg(b->k_pixels, 15, sizeof(cl_mem), &b->levels);
    rc |= clSetKernelArg(b->k_pixels, 16, sizeof(cl_mem), &b->have);
    rc |= clSetKernelArg(b->k_pixels, 17, sizeof(cl_mem), &b->where);
    rc |= next_epoch(b);
    rc |= clSetKernelArg(b->k_pixels, 18, sizeof(cl_uint), &b->epoch);
    rc |= clSetKernelArg(b->k_pixels, 19, sizeof(cl_mem), &b->out);
    rc |= clSetKernelArg(b->k_pixels, 20, sizeof(cl_mem), &b->pixel_shadow);
    rc |= clSetKernelArg(b->k_pixels, 21, sizeof(cl_mem), &b->corner_records);
    rc |= clSetKernelArg(b->k_pixels, 22, sizeof rh, &rh);
    const size_t per_item = (size_t)b->pix;
    size_t global = round_up(((size_t)count + per_item - 1) / per_item, b->local);
    if (rc != CL_SUCCESS)
        return rc;
    return clEnqueueNDRangeKernel(b->queue, b->k_pixels, 1, NULL, &global, &b->local, 0, NULL, ev);
}

/* One rectangle's render: its sizes, and the host buffers its results are read back into. */
typedef struct cl_task {
    tf_rect rect;
    size_t ncorners, npixels; /* the lattice corners (w+1 by h+1) and the pixels */
    size_t side;              /* a pixel's sample lattice: side by side samples */
    size_t batch;             /* pixels a launch of the pixel kernel covers */
    cl_uint *corner_shadow, *pixel_shadow; /* shadow rays per corner and per pixel */
    float *pix;               /* TF_CL_PIXEL_FLOATS a pixel */
} cl_task;

/* The rectangle's sizes, and the pixels a launch takes: as many as the sample caches of
 * b->scratch hold, whole work-items of b->pix pixels, at least one work-item. */
static void plan_task(const tf_cl_backend *b, tf_rect rect, cl_task *t)
{
    memset(t, 0, sizeof *t);
    t->rect = rect;
    t->ncorners = (size_t)(rect.w + 1) * (size_t)(rect.h + 1);
    t->npixels = (size_t)rect.w * (size_t)rect.h;
    t->side = (size_t)b->lattice + 1;
    const size_t per_pixel = t->side * t->side *
                             (TF_CL_SAMPLE_FLOATS * sizeof(float) + 3 * sizeof(double) +
                              sizeof(cl_uint) + sizeof(cl_uint)); /* have, where */
    const size_t per_item = (size_t)b->pix;
    t->batch = b->scratch / per_pixel / per_item * per_item;
    if (t->batch < per_item)
        t->batch = per_item;
    if (t->batch > t->npixels)
        t->batch = t->npixels;
}

static void free_task(cl_task *t)
{
    free(t->corner_shadow);
    free(t->pixel_shadow);
    free(t->pix);
}

/* The host buffers, and device buffers large enough for t.  0, or -1 without memory. */
static int alloc_task(tf_cl_backend *b, cl_task *t)
{
    const size_t nc = t->ncorners, np = t->npixels, cache = t->batch * t->side * t->side;
    t->corner_shadow = malloc(nc * sizeof *t->corner_shadow);
    t->pixel_shadow = malloc(np * sizeof *t->pixel_shadow);
    t->pix = malloc(np * TF_CL_PIXEL_FLOATS * sizeof *t->pix);
    int failed = !t->corner_shadow || !t->pixel_shadow || !t->pix ||
                 ensure(b, &b->corners, &b->corners_cap,
                        nc * TF_CL_SAMPLE_FLOATS * sizeof(float)) ||
                 ensure(b, &b->corner_levels, &b->corner_levels_cap, nc * 3 * sizeof(double)) ||
                 ensure(b, &b->corner_shadow, &b->corner_shadow_cap, nc * sizeof(cl_uint)) ||
                 ensure(b, &b->corner_records, &b->corner_records_cap,
                        nc * TF_CL_RECORD_DOUBLES * sizeof(double)) ||
                 ensure(b, &b->cache, &b->cache_cap, cache * TF_CL_SAMPLE_FLOATS * sizeof(float)) ||
                 ensure(b, &b->levels, &b->levels_cap, cache * 3 * sizeof(double)) ||
                 ensure_have(b, cache) ||
                 ensure(b, &b->where, &b->where_cap, cache * sizeof(cl_uint)) ||
                 ensure(b, &b->out, &b->out_cap, np * TF_CL_PIXEL_FLOATS * sizeof(float)) ||
                 ensure(b, &b->pixel_shadow, &b->pixel_shadow_cap, np * sizeof(cl_uint));
    return failed ? -1 : 0;
}

/* The corner kernel over the rectangle's lattice corners, a strip of them a work-item. */
static cl_int enqueue_corners(tf_cl_backend *b, tf_rect rect, cl_event *ev)
{
    cl_int cw = rect.w + 1, ch = rect.h + 1;
    cl_int rc = set_common_args(b, b->k_corners, rect);
    rc |= clSetKernelArg(b->k_corners, 9, sizeof cw, &cw);
    rc |= clSetKernelArg(b->k_corners, 10, sizeof ch, &ch);
    rc |= clSetKernelArg(b->k_corners, 11, sizeof(cl_mem), &b->corners);
    rc |= clSetKernelArg(b->k_corners, 12, sizeof(cl_mem), &b->corner_levels);
    rc |= clSetKernelArg(b->k_corners, 13, sizeof(cl_mem), &b->corner_shadow);
    rc |= clSetKernelArg(b->k_corners, 14, sizeof(cl_mem), &b->corner_records);
    const size_t strip = TF_CL_CORNER_STRIP((size_t)b->stream);
    size_t global = round_up(((size_t)cw + strip - 1) / strip, b->local);
    if (rc != CL_SUCCESS)
        return rc;
    return clEnqueueNDRangeKernel(b->queue, b->k_corners, 1, NULL, &global, &b->local, 0, NULL,
                                  ev);
}

/* The results read back, queued behind the kernels: the one clFinish after is the only wait. */
static cl_int enqueue_reads(tf_cl_backend *b, const cl_task *t)
{
    cl_int rc = clEnqueueReadBuffer(b->queue, b->out, CL_FALSE, 0,
                                    t->npixels * TF_CL_PIXEL_FLOATS * sizeof(float), t->pix, 0,
                                    NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clEnqueueReadBuffer(b->queue, b->corner_shadow, CL_FALSE, 0,
                                 t->ncorners * sizeof(cl_uint), t->corner_shadow, 0, NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clEnqueueReadBuffer(b->queue, b->pixel_shadow, CL_FALSE, 0,
                                 t->npixels * sizeof(cl_uint), t->pixel_shadow, 0, NULL, NULL);
    return rc;
}

/* Both kernels and the reads queued, waited for, and their device time counted. */
static cl_int run_task(tf_cl_backend *b, cl_task *t)
{
    cl_event corner_ev = NULL;
    cl_int rc = enqueue_corners(b, t->rect, &corner_ev);
    const size_t nbatches = (t->npixels + t->batch - 1) / t->batch;
    cl_event *pixel_ev = calloc(nbatches, sizeof *pixel_ev);
    if (!pixel_ev)
        rc = CL_OUT_OF_HOST_MEMORY;
    for (size_t i = 0; rc == CL_SUCCESS && i < nbatches; i++)
        rc = enqueue_pixel_batch(b, t->rect, i * t->batch, t->npixels, t->batch, &pixel_ev[i]);
    if (rc == CL_SUCCESS)
        rc = enqueue_reads(b, t);
    cl_int finished = clFinish(b->queue);
    if (rc == CL_SUCCESS)
        rc = finished;
    if (corner_ev)
        keep_first_error(&rc, account(corner_ev, &b->corner_seconds));
    for (size_t i = 0; pixel_ev && i < nbatches; i++)
        if (pixel_ev[i])
            keep_first_error(&rc, account(pixel_ev[i], &b->pixel_seconds));
    free(pixel_ev);
    return rc;
}

/* The pixels read back into out, and the rays they took into counts. */
static void deliver_task(const cl_task *t, tf_pixel *out, tf_render_counts *counts)
{
    uint64_t inner = 0; /* camera rays traced inside pixels, beyond the corners */
    for (size_t k = 0; k < t->npixels; k++) {
        const float *p = t->pix + k * TF_CL_PIXEL_FLOATS;
        out[k] = (tf_pixel){p[0], p[1], p[2], p[3], p[4], p[5]};
        inner += (uint64_t)p[6];
    }
    if (!counts)
        return;
    counts->primary_rays += t->ncorners + inner;
    counts->shadow_rays +=
        sum_u32(t->corner_shadow, t->ncorners) + sum_u32(t->pixel_shadow, t->npixels);
    counts->external_rays += (uint64_t)t->rect.w + (uint64_t)t->rect.h + 1;
    counts->pixels += t->npixels;
}

int tf_cl_backend_render(tf_cl_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                         char *err, size_t errlen)
{
    if (!b->renderer)
        return tf_seterr(err, errlen, "OpenCL: no scene attached to the backend");
    const tf_scene *s = b->renderer->scene;
    if (rect.w <= 0 || rect.h <= 0 || rect.x < 0 || rect.y < 0 || rect.x > s->width - rect.w ||
        rect.y > s->height - rect.h)
        return tf_seterr(err, errlen, "rectangle %dx%d+%d+%d outside the %dx%d image", rect.w,
                         rect.h, rect.x, rect.y, s->width, s->height);
    cl_task t;
    plan_task(b, rect, &t);
    if (alloc_task(b, &t)) {
        free_task(&t);
        return tf_seterr(err, errlen, "OpenCL: out of memory for a %dx%d rectangle", rect.w,
                         rect.h);
    }
    cl_int rc = run_task(b, &t);
    if (rc != CL_SUCCESS) {
        free_task(&t);
        return tf_seterr(err, errlen, "OpenCL: rendering %dx%d+%d+%d failed (error %d)", rect.w,
                         rect.h, rect.x, rect.y, rc);
    }
    deliver_task(&t, out, counts);
    free_task(&t);
    return 0;
}

/* A read-only buffer holding a copy of `bytes` of host memory (one byte if none, so a kernel
 * argument always has a buffer). */
static cl_mem buffer_of(tf_cl_backend *b, const void *host, size_t bytes, cl_int *rc)
{
    static const double none = 0;
    return clCreateBuffer(b->ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, host ? bytes : 1,
                          host ? (void *)host : (void *)&none, rc);
}

int tf_cl_backend_walk(tf_cl_backend *b, int n, const double *rays, const double *lows,
                       const double *fars, double *t, double *records, char *err,
                       size_t errlen)
{
    if (!b->renderer)
        return tf_seterr(err, errlen, "OpenCL: no scene attached to the backend");
    if (n <= 0)
        return 0;
    cl_int rc = CL_SUCCESS, has_lows = lows != NULL, has_fars = fars != NULL;
    cl_kernel k = clCreateKernel(b->program, "tf_walk_rays8", &rc);
    const size_t nr = (size_t)n * TF_CL_RECORD_DOUBLES * sizeof(double);
    cl_mem in = buffer_of(b, rays, (size_t)n * 7 * sizeof(double), &rc);
    cl_mem lo = buffer_of(b, lows, nr, &rc), fa = buffer_of(b, fars, nr, &rc);
    cl_mem tb = clCreateBuffer(b->ctx, CL_MEM_WRITE_ONLY, (size_t)n * sizeof(double), NULL, &rc);
    cl_mem rb = clCreateBuffer(b->ctx, CL_MEM_WRITE_ONLY, nr, NULL, &rc);
    if (k && in && lo && fa && tb && rb) {
        rc = set_world_args(b, k);
        rc |= clSetKernelArg(k, 7, sizeof(cl_int), &n);
        rc |= clSetKernelArg(k, 8, sizeof(cl_mem), &in);
        rc |= clSetKernelArg(k, 9, sizeof(cl_mem), &lo);
        rc |= clSetKernelArg(k, 10, sizeof(cl_int), &has_lows);
        rc |= clSetKernelArg(k, 11, sizeof(cl_mem), &fa);
        rc |= clSetKernelArg(k, 12, sizeof(cl_int), &has_fars);
        rc |= clSetKernelArg(k, 13, sizeof(cl_mem), &tb);
        rc |= clSetKernelArg(k, 14, sizeof(cl_mem), &rb);
        size_t global = round_up(((size_t)n + (size_t)b->stream - 1) / (size_t)b->stream, b->local);
        if (rc == CL_SUCCESS)
            rc = clEnqueueNDRangeKernel(b->queue, k, 1, NULL, &global, &b->local, 0, NULL, NULL);
        if (rc == CL_SUCCESS)
            rc = clEnqueueReadBuffer(b->queue, tb, CL_TRUE, 0, (size_t)n * sizeof(double), t, 0,
                                     NULL, NULL);
        if (rc == CL_SUCCESS)
            rc = clEnqueueReadBuffer(b->queue, rb, CL_TRUE, 0, nr, records, 0, NULL, NULL);
    } else if (rc == CL_SUCCESS) {
        rc = CL_OUT_OF_RESOURCES;
    }
    cl_mem bufs[] = {in, lo, fa, tb, rb};
    for (int i = 0; i < 5; i++)
        if (bufs[i])
            clReleaseMemObject(bufs[i]);
    if (k)
        clReleaseKernel(k);
    if (rc != CL_SUCCESS)
        return tf_seterr(err, errlen, "OpenCL: walking %d rays failed (error %d)", n, rc);
    return 0;
}

void tf_cl_backend_free(tf_cl_backend *b)
{
    if (!b)
        return;
    cl_mem bufs[] = {b->P,      b->I,     b->h,     b->minmax, b->perm, b->strips,
                     b->corners, b->corner_levels, b->corner_shadow, b->corner_records,
                     b->cache, b->levels,
                     b->have, b->where, b->out, b->pixel_shadow};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++)
        if (bufs[i])
            clReleaseMemObject(bufs[i]);
    free(b->minmax_host); /* after the buffer that read it in place */
    if (b->k_corners)
        clReleaseKernel(b->k_corners);
    if (b->k_pixels)
        clReleaseKernel(b->k_pixels);
    if (b->program)
        clReleaseProgram(b->program);
    if (b->queue)
        clReleaseCommandQueue(b->queue);
    if (b->ctx)
        clReleaseContext(b->ctx);
    tf_renderer_free(b->renderer);
    free(b);
}
