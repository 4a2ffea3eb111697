/* zz_pending.c: TEMPORARY.  Weak placeholder definitions of functions whose real (strong)
 * definitions are being written in parallel, so the tree links meanwhile.  Each one dies loudly.
 * This file must be deleted before the foundation is finished. */
#include <stdlib.h>
#include "exrfile.h"
#include "heightfield.h"
#include "log.h"
#include "noise.h"
#include "preview.h"
#include "render.h"
#include "scene.h"
#include "terrain.h"
#include "trace.h"

#define PENDING(name) tf_die(70, "%s is not implemented yet", name)
#define W __attribute__((weak))

W tf_scene *tf_scene_load(const char *a, char *b, size_t c) { (void)a; (void)b; (void)c; PENDING("tf_scene_load"); }
W tf_scene *tf_scene_parse_text(const char *a, const char *t, size_t l, char *b, size_t c) { (void)a; (void)t; (void)l; (void)b; (void)c; PENDING("tf_scene_parse_text"); }
W void tf_scene_free(tf_scene *s) { (void)s; PENDING("tf_scene_free"); }
W void tf_scene_set_size(tf_scene *s, int w, int h) { (void)s; (void)w; (void)h; PENDING("tf_scene_set_size"); }
W char *tf_scene_canonical(const tf_scene *s) { (void)s; PENDING("tf_scene_canonical"); }
W void tf_scene_rehash(tf_scene *s) { (void)s; PENDING("tf_scene_rehash"); }
W const char *tf_generator_name(enum tf_generator g) { (void)g; PENDING("tf_generator_name"); }
W double tf_terrain_point(const tf_terrain *t, const tf_noise *n, double x, double y) { (void)t; (void)n; (void)x; (void)y; PENDING("tf_terrain_point"); }
W int tf_gen_midpoint(float *h, int k, const tf_terrain *t, int th, char *e, size_t el) { (void)h; (void)k; (void)t; (void)th; (void)e; (void)el; PENDING("tf_gen_midpoint"); }
W int tf_gen_fault(float *h, int k, const tf_terrain *t, int th, char *e, size_t el) { (void)h; (void)k; (void)t; (void)th; (void)e; (void)el; PENDING("tf_gen_fault"); }
W int tf_gen_subdivide(float *h, int k, const tf_terrain *t, int th, char *e, size_t el) { (void)h; (void)k; (void)t; (void)th; (void)e; (void)el; PENDING("tf_gen_subdivide"); }
W int tf_weather_thermal(float *h, int n, double c, const tf_terrain *t, int th, char *e, size_t el) { (void)h; (void)n; (void)c; (void)t; (void)th; (void)e; (void)el; PENDING("tf_weather_thermal"); }
W tf_heightfield *tf_heightfield_build(const tf_scene *s, int t, char *e, size_t el) { (void)s; (void)t; (void)e; (void)el; PENDING("tf_heightfield_build"); }
W tf_heightfield *tf_heightfield_from_heights(const float *h, int k, double e, int t) { (void)h; (void)k; (void)e; (void)t; PENDING("tf_heightfield_from_heights"); }
W tf_heightfield *tf_heightfield_wrap(float *h, int k, double e, int t) { (void)h; (void)k; (void)e; (void)t; PENDING("tf_heightfield_wrap"); }
W void tf_heightfield_free(tf_heightfield *h) { (void)h; PENDING("tf_heightfield_free"); }
W double tf_heightfield_height_at(const tf_heightfield *h, double x, double y) { (void)h; (void)x; (void)y; PENDING("tf_heightfield_height_at"); }
W int tf_thread_count(int t) { (void)t; PENDING("tf_thread_count"); }
W void tf_noise_init(tf_noise *n, uint64_t s) { (void)n; (void)s; PENDING("tf_noise_init"); }
W double tf_noise2(const tf_noise *n, double x, double y) { (void)n; (void)x; (void)y; PENDING("tf_noise2"); }
W double tf_noise3(const tf_noise *n, double x, double y, double z) { (void)n; (void)x; (void)y; (void)z; PENDING("tf_noise3"); }
W double tf_fbm2(const tf_noise *n, double x, double y, double H, double l, double o) { (void)n; (void)x; (void)y; (void)H; (void)l; (void)o; PENDING("tf_fbm2"); }
W double tf_fbm3(const tf_noise *n, double x, double y, double z, double H, double l, double o) { (void)n; (void)x; (void)y; (void)z; (void)H; (void)l; (void)o; PENDING("tf_fbm3"); }
W tf_renderer *tf_renderer_new(const tf_scene *s, const tf_heightfield *h, char *e, size_t el) { (void)s; (void)h; (void)e; (void)el; PENDING("tf_renderer_new"); }
W void tf_renderer_free(tf_renderer *r) { (void)r; PENDING("tf_renderer_free"); }
W void tf_render_rect(const tf_renderer *r, tf_rect rc, tf_pixel *o, tf_render_counts *c) { (void)r; (void)rc; (void)o; (void)c; PENDING("tf_render_rect"); }
W int tf_trace(const tf_heightfield *h, tf_vec3 o, tf_vec3 d, double a, double b, tf_hit *hit) { (void)h; (void)o; (void)d; (void)a; (void)b; (void)hit; PENDING("tf_trace"); }
W int tf_trace_flat(const tf_heightfield *h, tf_vec3 o, tf_vec3 d, double a, double b, tf_hit *hit) { (void)h; (void)o; (void)d; (void)a; (void)b; (void)hit; PENDING("tf_trace_flat"); }
W int tf_occluded(const tf_heightfield *h, tf_vec3 o, tf_vec3 d, double a, double b) { (void)h; (void)o; (void)d; (void)a; (void)b; PENDING("tf_occluded"); }
W int tf_exr_chunk_rows(void) { PENDING("tf_exr_chunk_rows"); }
W tf_exr_writer *tf_exr_create(const char *p, const tf_exr_meta *m, char *e, size_t el) { (void)p; (void)m; (void)e; (void)el; PENDING("tf_exr_create"); }
W int tf_exr_write_rows(tf_exr_writer *w, int n, const tf_pixel *p, char *e, size_t el) { (void)w; (void)n; (void)p; (void)e; (void)el; PENDING("tf_exr_write_rows"); }
W int tf_exr_next_row(const tf_exr_writer *w) { (void)w; PENDING("tf_exr_next_row"); }
W int tf_exr_sync(tf_exr_writer *w, char *e, size_t el) { (void)w; (void)e; (void)el; PENDING("tf_exr_sync"); }
W int tf_exr_finish(tf_exr_writer *w, char *e, size_t el) { (void)w; (void)e; (void)el; PENDING("tf_exr_finish"); }
W void tf_exr_abandon(tf_exr_writer *w) { (void)w; PENDING("tf_exr_abandon"); }
W int tf_exr_probe(const char *p, tf_exr_meta *m, int *r, int *c, char *e, size_t el) { (void)p; (void)m; (void)r; (void)c; (void)e; (void)el; PENDING("tf_exr_probe"); }
W tf_exr_writer *tf_exr_resume(const char *p, const tf_exr_meta *m, int *r, char *e, size_t el) { (void)p; (void)m; (void)r; (void)e; (void)el; PENDING("tf_exr_resume"); }
W int tf_exr_read_rows(const char *p, tf_exr_meta *m, int *r, tf_exr_row_fn f, void *u, char *e, size_t el) { (void)p; (void)m; (void)r; (void)f; (void)u; (void)e; (void)el; PENDING("tf_exr_read_rows"); }
W int tf_exr_write_gray(const char *p, int w, int h, const float *d, char *e, size_t el) { (void)p; (void)w; (void)h; (void)d; (void)e; (void)el; PENDING("tf_exr_write_gray"); }
W uint8_t tf_srgb8(float l) { (void)l; PENDING("tf_srgb8"); }
W int tf_preview_from_exr(const char *a, const char *b, char *e, size_t el) { (void)a; (void)b; (void)e; (void)el; PENDING("tf_preview_from_exr"); }
