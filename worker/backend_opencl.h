/* backend_opencl.h: the OpenCL backend (PoCL on the CPU, any OpenCL GPU elsewhere): the same
 * renderer as common/render/render.h, as OpenCL C 1.2 kernels in worker/kernels/. */
#ifndef TF_BACKEND_OPENCL_H
#define TF_BACKEND_OPENCL_H

#include <stddef.h>
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"

typedef struct tf_cl_backend tf_cl_backend;

/* What the kernels cannot render, said in one place, or NULL: a procedural terrain (they walk
 * a grid's max/min mipmap, of which it has none) or an eroded one (they do not read its water
 * and silt maps, and would shade it dry).  The backend asks it of the height field it is given;
 * tf_cl_scene_unsupported of a scene: the coordinator, before it builds the terrain, and a
 * networked worker, before it starts a device ahead. */
const char *tf_cl_terrain_unsupported(int procedural, int eroded);
const char *tf_cl_scene_unsupported(const tf_scene *s);

/* Choose a platform and device (TERRAFARM_CL_DEVICE overrides: "platform:device" indices or a
 * substring of the device name), build the kernels (showing the build log on failure),
 * upload the height field and its max grids.  NULL with a one-line message on failure. */
tf_cl_backend *tf_cl_backend_new(const tf_scene *s, const tf_heightfield *hf, char *err,
                                 size_t errlen);
/* tf_cl_backend_new in two parts, so that the first can run while the terrain is built (on
 * the thread of worker/opencl_ahead.h): open starts the device (platform, context, queue, the
 * program through the binary cache), which needs no scene; attach gives it the scene and the
 * height field (0, or -1 with a message: the backend may then only be freed).  A backend is
 * attached once; until then render and set_scene refuse. */
tf_cl_backend *tf_cl_backend_open(char *err, size_t errlen);
int tf_cl_backend_attach(tf_cl_backend *b, const tf_scene *s, const tf_heightfield *hf, char *err,
                         size_t errlen);
/* Point PoCL at terrafarm's cache directory (unless the user chose one: POCL_CACHE_DIR, set
 * with setenv) and sweep from it the empty files PoCL's start-up leaves there
 * (pocl_cachedir.h).  Once a process, before the first OpenCL call; open calls it, and whoever
 * opens on a thread calls it first on its own, since setenv must not run beside other threads'
 * getenv. */
void tf_cl_prepare_environment(void);
int tf_cl_backend_render(tf_cl_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                         char *err, size_t errlen);
void tf_cl_backend_free(tf_cl_backend *b);
/* The kernels' ray walk (packet_trace.cl's walk_stream) on n rays of the caller's, against the
 * attached height field, for tests and benchmarks: ray k is rays[7k .. 7k+6] (origin, direction,
 * tmax; tmin 0); if lows is not NULL, lows[5k .. 5k+4] is the coherence record that helps it
 * (trace.h's tf_ray_clear without the origin: ux, uy, k, s_in, s_free; it must be a record of a
 * ray from ray k's own origin), and if fars is not NULL, fars[5k ..] is the one asked where
 * that one cannot vouch (the pixel kernel's far corner).  Out: t[k], the hit's parameter
 * (INFINITY: no hit), and records[5k ..], ray k's own record.  0, or -1 with a message. */
int tf_cl_backend_walk(tf_cl_backend *b, int n, const double *rays, const double *lows,
                       const double *fars, double *t, double *records, char *err,
                       size_t errlen);
/* Render s from now on: a scene that differs from the backend's only in camera and sun (a
 * frame of the same sequence, tf_scene_at_frame).  Uploads the new parameters (a few hundred
 * bytes); the program and the height field stay.  s must outlive the backend's use of it.
 * 0, or -1 with a message (the backend then still renders its previous scene). */
int tf_cl_backend_set_scene(tf_cl_backend *b, const tf_scene *s, char *err, size_t errlen);
/* The chosen device's name, and the seconds making the program took (from the binary cache,
 * or clBuildProgram from source: a PoCL cache hit is faster than a cold build). */
const char *tf_cl_backend_device(const tf_cl_backend *b);
double tf_cl_backend_build_seconds(const tf_cl_backend *b);
/* How the program was made, by the binary cache (worker/opencl_cache.h): "hit", "miss" (built
 * and stored), "rebuilt" (the entry was refused, built and stored again), "refused" (the
 * directory was: built, not stored) or "off" (TF_OPENCL_CACHE=off). */
const char *tf_cl_backend_cache(const tf_cl_backend *b);
/* Device seconds spent so far in the corner and the pixel kernels (profiling events). */
void tf_cl_backend_kernel_seconds(const tf_cl_backend *b, double *corners, double *pixels);

#endif
