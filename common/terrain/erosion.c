/* erosion.c: the erosion model's constants (tf_erosion_model_init), its rain schedule, and the
 * conversions between world heights and the integer state (erosion.h). */
#include "terrain/erosion.h"
#include "terrain/erosion_state.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/gridgen.h"
#include "terrain/noise.h"
#include "log.h"

/* The quantum: the power of two that puts the initial range into 2^TF_EROSION_RANGE_BITS. */
static double quantum_for(double range)
{
    if (!(range > 1e-6))
        range = 1e-6;
    return ldexp(1.0, (int)ceil(log2(range)) - TF_EROSION_RANGE_BITS);
}

int tf_erosion_model_init(tf_erosion_model *m, const tf_erosion_keys *k, uint64_t seed, int n,
                          float hmin, float hmax, char *err, size_t errlen)
{
    if (!isfinite(hmin) || !isfinite(hmax) || hmax < hmin || n < 3) {
        tf_seterr(err, errlen, "erosion: needs a grid of at least 3x3 finite heights");
        return -1;
    }
    memset(m, 0, sizeof *m);
    double range = (double)hmax - (double)hmin;
    m->n = n;
    /* the quanta must also hold the water that rains: a flat plane still collects it */
    double storm = k->rain * (1.0 + k->rain_altitude) * (1.0 + 4.0 * k->rain_noise);
    m->q = quantum_for(fmax(fmax(range, 64.0 * storm), 1.0));
    m->base = hmin;
    m->kc = (float)k->capacity;
    m->kd = (float)k->deposition;
    m->ks = (float)k->softness;
    m->k_silt = (float)(k->softness * k->silt_softness);
    m->k_talus = (float)(k->softness * k->talus_softness);
    m->creep = (float)k->creep;
    m->evaporation = (float)k->evaporation;
    m->flow_decay = 0.99f;
    m->rain_altitude = (float)k->rain_altitude;
    double range_units = range / m->q;
    m->inv_range_units = range_units > 0 ? (float)(1.0 / range_units) : 0.0f;
    m->inv_strata_units = k->strata > 0 ? (float)(m->q / k->strata) : 0.0f;
    m->strata_contrast = (float)k->strata_contrast;
    m->rain_units = k->rain / m->q;
    m->rain_interval = k->rain_interval > 0 ? k->rain_interval : 1;
    m->rain_noise = k->rain_noise;
    m->seed = seed;
    m->steps = k->fluvial_steps;
    return 0;
}

/* A 1/f sequence over rain events (Voss-McCartney): the sum of 8 octaves, octave o a Gaussian
 * draw held for 2^o events, normalised to unit variance. */
static double pink(uint64_t seed, int event)
{
    double sum = 0.0;
    for (int o = 0; o < 8; o++)
        sum += tf_grid_gauss(tf_grid_key(seed, 0x7261696e /* "rain" */, (uint32_t)o,
                                         (uint32_t)(event >> o), 0));
    return sum * 0.35355339059327373; /* 1 / sqrt(8) */
}

float tf_erosion_rain_now(const tf_erosion_model *m, int step)
{
    if (step % m->rain_interval != 0 || !(m->rain_units > 0))
        return 0.0f;
    double storm = 1.0;
    if (m->rain_noise > 0)
        storm = fmax(0.0, 1.0 + m->rain_noise * pink(m->seed, step / m->rain_interval));
    return (float)(m->rain_units * storm);
}

/* The bedrock softness field: 1 + hardness_noise * fBm, clamped to [0.05, 2]. */
static void fill_softness(float *soft, int n, const tf_erosion_keys *k, uint64_t seed)
{
    if (!(k->hardness_noise > 0)) {
        for (size_t i = 0; i < (size_t)n * (size_t)n; i++)
            soft[i] = 1.0f;
        return;
    }
    tf_noise nz;
    tf_noise_init(&nz, seed ^ 0x68617264ull /* "hard" */);
    double f = 8.0 / (double)(n - 1); /* 8 features across the grid */
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            double v = 1.0 + k->hardness_noise * tf_fbm2(&nz, i * f, j * f, 0.7, 2.0, 5.0);
            soft[(size_t)j * (size_t)n + (size_t)i] = (float)fmin(2.0, fmax(0.05, v));
        }
}

int tf_erosion_state_from_heights(tf_erosion_state *st, const tf_erosion_model *m,
                                  const tf_erosion_keys *k, const float *h)
{
    size_t count = (size_t)m->n * (size_t)m->n;
    if (tf_erosion_state_alloc(st, m->n) != 0)
        return -1;
    for (size_t i = 0; i < count; i++) {
        double a = nearbyint(((double)h[i] - m->base) / m->q);
        st->b[i] = (int32_t)a;
    }
    fill_softness(st->soft, m->n, k, m->seed);
    return 0;
}

int tf_erosion_begin(const tf_terrain *t, const float *h, int n, tf_erosion_model *m,
                     tf_erosion_state *st, char *err, size_t errlen)
{
    float lo = h[0], hi = h[0];
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++) {
        lo = h[i] < lo ? h[i] : lo;
        hi = h[i] > hi ? h[i] : hi;
    }
    if (tf_erosion_model_init(m, &t->erosion, t->seed, n, lo, hi, err, errlen) != 0)
        return -1;
    if (tf_erosion_state_from_heights(st, m, &t->erosion, h) != 0)
        return tf_seterr(err, errlen, "out of memory: erosion of a %dx%d grid", n, n);
    return 0;
}

void tf_erosion_heights(const tf_erosion_state *st, const tf_erosion_model *m, float *h)
{
    size_t count = (size_t)m->n * (size_t)m->n;
    for (size_t i = 0; i < count; i++) {
        int64_t a = (int64_t)st->b[i] + st->t[i] + st->d[i];
        h[i] = (float)(m->base + (double)a * m->q);
    }
}

int64_t tf_erosion_solid(const tf_erosion_state *st, int n)
{
    int64_t sum = 0;
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++)
        sum += (int64_t)st->b[i] + st->t[i] + st->d[i] + st->s[i];
    return sum;
}

int64_t tf_erosion_water(const tf_erosion_state *st, int n)
{
    int64_t sum = 0;
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++)
        sum += st->w[i];
    return sum;
}
