/* opencl_cache.h: a per-user on-disk cache of compiled OpenCL programs, so that a worker
 * process creates its program from the binary an earlier process built (clCreateProgramWithBinary)
 * instead of compiling the kernels from source in every process (about 0.18 s a process on
 * PoCL even when PoCL's own cache hits: it still preprocesses and hashes the source).
 *
 * One entry per program and device: a file named by its key, a BLAKE2b hash (libsodium) of the
 * kernel source bytes, the build options, the platform's name and version and the device's
 * name, version and driver version, so a new source, option, driver or device never meets an
 * old entry.  The entry is an 88-byte header (magic, format version, the key, the binary's
 * length and its BLAKE2b checksum), then the binary.  Anything that does not check out -- the
 * directory not the user's own or writable by others, a header or checksum that differs, a
 * binary the driver rejects -- means building from source, and rewriting the entry.  Loading an
 * entry marks its last use (its time); storing one removes the entries not used for
 * TF_CLCACHE_MAX_IDLE_S (tf_clcache_prune): a new source or driver leaves the old entries
 * behind, and nothing else would ever remove them. */
#ifndef TF_OPENCL_CACHE_H
#define TF_OPENCL_CACHE_H

#ifndef CL_TARGET_OPENCL_VERSION
#define CL_TARGET_OPENCL_VERSION 120
#endif
#include <CL/cl.h>
#include <limits.h>
#include <stddef.h>
#include <time.h>

#define TF_CLCACHE_KEY_BYTES 32
#define TF_CLCACHE_MAX_IDLE_S (30L * 86400) /* an entry unused this long goes (30 days) */
#define TF_CLCACHE_HEADER_BYTES 88

/* How a backend's program was made (tf_cl_backend_cache). */
enum tf_clcache_state {
    TF_CLCACHE_OFF,     /* TF_OPENCL_CACHE=off: built from source, nothing stored */
    TF_CLCACHE_REFUSED, /* the directory is unsafe or unusable: built from source, nothing stored */
    TF_CLCACHE_HIT,     /* made from the stored binary */
    TF_CLCACHE_MISS,    /* no entry: built from source, and stored */
    TF_CLCACHE_REBUILT, /* the entry was refused (header, checksum, or the driver rejected it):
                           built from source, and the entry rewritten */
};

typedef struct tf_clcache {
    int dirfd;                /* the checked cache directory; -1 when off or refused */
    char dir[PATH_MAX];
    char name[2 * TF_CLCACHE_KEY_BYTES + 8]; /* the entry's file name: the key in hex, ".bin" */
    unsigned char key[TF_CLCACHE_KEY_BYTES];
    enum tf_clcache_state state;
} tf_clcache;

/* Open the cache for the program built from src[0..nsrc) with `options` on dev.  The directory
 * is $TF_OPENCL_CACHE, else $XDG_CACHE_HOME/terrafarm/opencl, else $HOME/.cache/terrafarm/opencl,
 * created (0700) if absent; TF_OPENCL_CACHE=off turns the cache off.  0 when usable (c->state is
 * MISS until something else is known); else -1 with c->state OFF (err empty) or REFUSED (err
 * says why: not owned by this user, writable by group or others, not a directory...). */
int tf_clcache_open(tf_clcache *c, cl_device_id dev, cl_uint nsrc, const char *const *src,
                    const size_t *len, const char *options, char *err, size_t errlen);
void tf_clcache_close(tf_clcache *c);

/* The program made from the entry's binary and built for dev with `options`.  NULL if there is
 * no entry (err empty) or it was refused (err says why, and the caller rebuilds and stores). */
cl_program tf_clcache_load(const tf_clcache *c, cl_context ctx, cl_device_id dev,
                           const char *options, char *err, size_t errlen);

/* Store prog's binary (one device) as the entry: a temporary file of mode 0600 renamed over it,
 * so a reader sees the old entry, the new one or none.  A PoCL 3.1 binary is stored without its
 * LLVM IR (pocl_binary.h), so that loading it starts no compiler.  0, or -1 with a message. */
int tf_clcache_store(const tf_clcache *c, cl_program prog, char *err, size_t errlen);
/* The same with the binary's bytes given (what tf_clcache_store writes; tests store binaries a
 * driver rejects with it). */
int tf_clcache_write(const tf_clcache *c, const unsigned char *bin, size_t len, char *err,
                     size_t errlen);

/* Remove from the cache's directory every entry (a file named as tf_clcache names them, or a
 * temporary file of tf_clcache_write's) of this user's last used before now - max_idle_s,
 * except c's own; other names, links and other users' files stay.  How many went, or -1 when
 * the cache is not open or its directory cannot be read. */
int tf_clcache_prune(const tf_clcache *c, time_t now, long max_idle_s);

/* "off", "refused", "hit", "miss", "rebuilt". */
const char *tf_clcache_state_name(enum tf_clcache_state s);

#endif
