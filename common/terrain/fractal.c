/* fractal.c: fBm and Musgrave's heterogeneous, hybrid and ridged multifractal terrains
 * (fractal.h), and tf_terrain_point (terrain.h), the point-generator entry the rest of the
 * program uses.
 *
 * Each spectral sum is one static inline function of (noise-space x, per-octave y axes).  The
 * noise-space wrappers, tf_fractal_eval and tf_fractal_row all call these same functions, so a
 * height-field row built by tf_fractal_row is bit-identical to evaluating each of its points
 * alone (tests/unit/test_fractal.c checks it). */
#include "terrain/fractal.h"
#include "terrain/noise_row.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

static inline double clamp01(double v) { return v < 0.0 ? 0.0 : v > 1.0 ? 1.0 : v; }

static inline double hetero_axes(const tf_noise *nz, const tf_octaves *o, double offset, double x,
                                 const tf_noise_axis *axes)
{
    double altitude = tf_noise2_axis(nz, x, &axes[0]) + offset;
    for (int i = 1; i < o->count; i++) {
        x *= o->lacunarity;
        double increment = (tf_noise2_axis(nz, x, &axes[i]) + offset) * o->amp[i];
        altitude += altitude * increment;
    }
    return altitude;
}

static inline double hybrid_axes(const tf_noise *nz, const tf_octaves *o, double offset,
                                 double gain, double x, const tf_noise_axis *axes)
{
    double signal = 0.5 * (tf_noise2_axis(nz, x, &axes[0]) + offset);
    double result = signal;
    for (int i = 1; i < o->count; i++) {
        x *= o->lacunarity;
        double weight = clamp01(signal * gain);
        signal = weight * 0.5 * (tf_noise2_axis(nz, x, &axes[i]) + offset);
        result += o->amp[i] * signal;
    }
    return result;
}

static inline double ridge(double offset, double n)
{
    double r = offset - fabs(n);
    return r * r;
}

static inline double ridged_axes(const tf_noise *nz, const tf_octaves *o, double offset,
                                 double gain, double x, const tf_noise_axis *axes)
{
    double signal = ridge(offset, tf_noise2_axis(nz, x, &axes[0]));
    double result = signal;
    for (int i = 1; i < o->count; i++) {
        x *= o->lacunarity;
        double weight = clamp01(signal * gain);
        signal = weight * ridge(offset, tf_noise2_axis(nz, x, &axes[i]));
        result += o->amp[i] * signal;
    }
    return result;
}

double tf_hetero2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset)
{
    tf_octaves o;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octaves_plan(&o, H, lacunarity, octaves);
    tf_octave_axes(&o, y, axes);
    return hetero_axes(nz, &o, offset, x, axes);
}

double tf_hybrid2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset, double gain)
{
    tf_octaves o;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octaves_plan(&o, H, lacunarity, octaves);
    tf_octave_axes(&o, y, axes);
    return hybrid_axes(nz, &o, offset, gain, x, axes);
}

double tf_ridged2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset, double gain)
{
    tf_octaves o;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octaves_plan(&o, H, lacunarity, octaves);
    tf_octave_axes(&o, y, axes);
    return ridged_axes(nz, &o, offset, gain, x, axes);
}

void tf_fractal_seed_offset(uint64_t seed, double *ox, double *oy)
{
    /* Integer part in [16, 240), fraction in [0.1, 0.9]: far from any lattice line. */
    uint64_t a = tf_hash64(seed ^ 0x6a09e667f3bcc908ULL);
    uint64_t b = tf_hash64(seed ^ 0xbb67ae8584caa73bULL);
    *ox = (double)(16 + (a >> 32) % 224) + 0.1 + 0.8 * tf_hash_unit(a);
    *oy = (double)(16 + (b >> 32) % 224) + 0.1 + 0.8 * tf_hash_unit(b);
}

int tf_fractal_prepare(tf_fractal *f, const tf_terrain *t)
{
    switch (t->generator) {
    case TF_GEN_FBM:
    case TF_GEN_HETERO:
    case TF_GEN_HYBRID:
    case TF_GEN_RIDGED:
        break;
    default:
        return -1;
    }
    f->generator = t->generator;
    tf_octaves_plan(&f->octaves, t->H, t->lacunarity, t->octaves);
    f->H = t->H;
    f->offset = t->offset;
    f->gain = t->gain;
    f->feature_size = t->feature_size;
    tf_fractal_seed_offset(t->seed, &f->ox, &f->oy);
    return 0;
}

/* Value at noise-space x given the y axes of every octave. */
static inline double eval_axes(const tf_fractal *f, const tf_noise *nz, double x,
                               const tf_noise_axis *axes)
{
    switch (f->generator) {
    case TF_GEN_HETERO:
        return hetero_axes(nz, &f->octaves, f->offset, x, axes);
    case TF_GEN_HYBRID:
        return hybrid_axes(nz, &f->octaves, f->offset, f->gain, x, axes);
    case TF_GEN_RIDGED:
        return ridged_axes(nz, &f->octaves, f->offset, f->gain, x, axes);
    default:
        return tf_fbm2_axes(nz, &f->octaves, x, axes);
    }
}

double tf_fractal_eval(const tf_fractal *f, const tf_noise *nz, double x, double y)
{
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octave_axes(&f->octaves, y / f->feature_size + f->oy, axes);
    return eval_axes(f, nz, x / f->feature_size + f->ox, axes);
}

int tf_fractal_rowbuf_init(tf_fractal_rowbuf *buf, int capacity)
{
    memset(buf, 0, sizeof *buf);
    if (capacity < 1 || capacity > TF_FRACTAL_ROW_MAX)
        return -1;
    size_t n = (size_t)capacity;
    buf->x = malloc(n * sizeof *buf->x);
    buf->value = malloc(n * sizeof *buf->value);
    buf->signal = malloc(n * sizeof *buf->signal);
    buf->noise = malloc(n * sizeof *buf->noise);
    /* A row spans at most capacity + 2 columns whenever the table is used (see noise_row);
     * the vector blend may load (not use) a few past the end. */
    buf->columns = calloc(n + 2 + TF_NOISE_ROW_SLACK, sizeof *buf->columns);
    if (!buf->x || !buf->value || !buf->signal || !buf->noise || !buf->columns) {
        tf_fractal_rowbuf_free(buf);
        return -1;
    }
    buf->capacity = capacity;
    return 0;
}

void tf_fractal_rowbuf_free(tf_fractal_rowbuf *buf)
{
    free(buf->x);
    free(buf->value);
    free(buf->signal);
    free(buf->noise);
    free(buf->columns);
    memset(buf, 0, sizeof *buf);
}

/* noise[k] = tf_noise2_axis(nz, x[k], ay) for k in [0, count).
 *
 * Invariant used: x[] is monotonic in k (it is k * cell / feature_size + ox multiplied by the
 * lacunarity octave after octave, and IEEE rounding is monotonic), so floor(x[k]) lies between
 * the floors of the two ends and every column index below is within the table.  When the
 * octave's lattice is finer than the samples (more columns than samples) the table would cost
 * more than it saves, and each sample hashes its own two columns: same operations, same bits.
 * The blend from the table runs many samples at a time where the CPU can (noise_row.h). */
static void noise_row(const tf_noise *nz, const tf_noise_axis *ay, const double *x, int count,
                      double *noise, tf_noise_column *columns)
{
    double lo = x[0] < x[count - 1] ? x[0] : x[count - 1];
    double hi = x[0] < x[count - 1] ? x[count - 1] : x[0];
    int in_range = ay->ok && fabs(lo) < TF_NOISE_COORD_LIMIT && fabs(hi) < TF_NOISE_COORD_LIMIT;
    int64_t first = in_range ? tf_floor_i64(lo) : 0;
    int64_t span = in_range ? tf_floor_i64(hi) - first + 2 : 0;
    if (!in_range || span > (int64_t)count + 2) {
        for (int k = 0; k < count; k++)
            noise[k] = tf_noise2_axis(nz, x[k], ay);
        return;
    }
    for (int64_t c = 0; c < span; c++)
        columns[c] = tf_noise_column_at(nz, first + c, ay);
    for (int k = tf_noise_row_blend(x, count, first, columns, noise); k < count; k++) {
        double fx;
        int64_t xi = tf_floor_split(x[k], &fx);
        const tf_noise_column *c = &columns[xi - first];
        noise[k] = tf_noise_blend(fx, c[0], c[1]);
    }
}

/* The spectral sums of hetero_axes / hybrid_axes / ridged_axes / tf_fbm2_axes, reorganised
 * octave-major over a row.  Each sample sees exactly the same sequence of operations as in
 * the point functions above. */
static void row_octaves(const tf_fractal *f, const tf_noise *nz, const tf_noise_axis *axes,
                        int count, tf_fractal_rowbuf *b)
{
    const tf_octaves *o = &f->octaves;
    const double offset = f->offset, gain = f->gain, lacunarity = o->lacunarity;
    /* restrict and the local constants let the compiler pair the multifractals' loops;
     * x's scaling and fBm's sum run eight at a time where the CPU can (noise_row.h) */
    double *restrict x = b->x, *restrict v = b->value, *restrict s = b->signal;
    const double *restrict n = b->noise;
    for (int i = 0; i < o->count; i++) {
        if (i > 0)
            tf_row_scale(x, count, lacunarity);
        noise_row(nz, &axes[i], x, count, b->noise, b->columns);
        const double amp = o->amp[i];
        switch (f->generator) {
        case TF_GEN_HETERO:
            if (i == 0)
                for (int k = 0; k < count; k++) v[k] = n[k] + offset;
            else
                for (int k = 0; k < count; k++) v[k] += v[k] * ((n[k] + offset) * amp);
            break;
        case TF_GEN_HYBRID:
            if (i == 0)
                for (int k = 0; k < count; k++) v[k] = s[k] = 0.5 * (n[k] + offset);
            else
                for (int k = 0; k < count; k++) {
                    s[k] = clamp01(s[k] * gain) * 0.5 * (n[k] + offset);
                    v[k] += amp * s[k];
                }
            break;
        case TF_GEN_RIDGED:
            if (i == 0)
                for (int k = 0; k < count; k++) v[k] = s[k] = ridge(offset, n[k]);
            else
                for (int k = 0; k < count; k++) {
                    s[k] = clamp01(s[k] * gain) * ridge(offset, n[k]);
                    v[k] += amp * s[k];
                }
            break;
        default:
            if (i == 0)
                for (int k = 0; k < count; k++) v[k] = 0.0;
            tf_row_accumulate(v, amp, n, count);
            break;
        }
    }
}

void tf_fractal_row(const tf_fractal *f, const tf_noise *nz, double y, double cell, int count,
                    double scale, float *out, tf_fractal_rowbuf *buf)
{
    tf_fractal_row_at(f, nz, y, cell, 0, count, scale, out, buf);
}

void tf_fractal_row_at(const tf_fractal *f, const tf_noise *nz, double y, double cell,
                       int64_t first, int count, double scale, float *out,
                       tf_fractal_rowbuf *buf)
{
    if (count <= 0)
        return;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octave_axes(&f->octaves, y / f->feature_size + f->oy, axes);
    if (!buf || buf->capacity < count) {
        for (int k = 0; k < count; k++) {
            double x = (double)(first + k) * cell / f->feature_size + f->ox;
            out[k] = (float)(scale * eval_axes(f, nz, x, axes));
        }
        return;
    }
    double *restrict x = buf->x;
    const double feature_size = f->feature_size, ox = f->ox;
    for (int k = 0; k < count; k++)
        x[k] = (double)(first + k) * cell / feature_size + ox;
    row_octaves(f, nz, axes, count, buf);
    const double *restrict value = buf->value;
    for (int k = 0; k < count; k++)
        out[k] = (float)(scale * value[k]);
}

double tf_terrain_point(const tf_terrain *t, const tf_noise *noise, double x, double y)
{
    tf_fractal f;
    if (tf_fractal_prepare(&f, t) != 0)
        return 0.0; /* grid generators have no point form; see terrain.h */
    return tf_fractal_eval(&f, noise, x, y);
}
