/* noise.c: seeded Perlin gradient noise in 2D and 3D and its fBm sums (noise.h).
 *
 * The permutation is a Fisher-Yates shuffle of 0..255 driven by tf_hash64 of the seed, stored
 * twice (perm[256 + i] == perm[i]) so lattice hashing never needs a modulo.  The 2D kernel and
 * the octave plan live in noise_impl.h because fractal.c evaluates the same code a row at a
 * time; this file is the point-at-a-time face of it, plus 3D noise (textures, bump detail). */
#include "terrain/noise.h"
#include "terrain/noise_impl.h"

void tf_noise_init(tf_noise *nz, uint64_t seed)
{
    nz->seed = seed;
    for (int i = 0; i < TF_NOISE_LATTICE; i++)
        nz->perm[i] = (uint16_t)i;
    for (int i = TF_NOISE_LATTICE - 1; i > 0; i--) {
        /* The modulo bias (at most 256 / 2^64) is irrelevant; what matters is that the same seed
         * gives the same permutation everywhere. */
        uint64_t r = tf_hash64(seed ^ (0xd1b54a32d192ed03ULL * (uint64_t)(i + 1)));
        int j = (int)(r % (uint64_t)(i + 1));
        uint16_t tmp = nz->perm[i];
        nz->perm[i] = nz->perm[j];
        nz->perm[j] = tmp;
    }
    for (int i = 0; i < TF_NOISE_LATTICE; i++)
        nz->perm[TF_NOISE_LATTICE + i] = nz->perm[i];
}

double tf_noise2(const tf_noise *nz, double x, double y)
{
    tf_noise_axis ay;
    tf_noise_axis_set(&ay, y);
    return tf_noise2_axis(nz, x, &ay);
}

double tf_noise2_gradient(const tf_noise *nz, double x, double y, double *gx, double *gy)
{
    tf_noise_axis ay;
    tf_noise_axis_set(&ay, y);
    return tf_noise2_gradient_axis(nz, x, &ay, tf_fade_slope(ay.f0), gx, gy);
}

/* 3D gradients: Perlin's 12 cube edge directions (length sqrt 2), padded to 16 with four of
 * them repeated so the hash can be masked with 15 (Perlin 2002). */
static inline double grad3_dot(unsigned h, double x, double y, double z)
{
    switch (h & 15) {
    case 0:  return x + y;
    case 1:  return -x + y;
    case 2:  return x - y;
    case 3:  return -x - y;
    case 4:  return x + z;
    case 5:  return -x + z;
    case 6:  return x - z;
    case 7:  return -x - z;
    case 8:  return y + z;
    case 9:  return -y + z;
    case 10: return y - z;
    case 11: return -y - z;
    case 12: return x + y;
    case 13: return -x + y;
    case 14: return -y + z;
    default: return -y - z;
    }
}

static inline double lerp(double t, double a, double b) { return a + t * (b - a); }

double tf_noise3(const tf_noise *nz, double x, double y, double z)
{
    if (!(fabs(x) < TF_NOISE_COORD_LIMIT && fabs(y) < TF_NOISE_COORD_LIMIT &&
          fabs(z) < TF_NOISE_COORD_LIMIT))
        return 0.0;
    int64_t xi = tf_floor_i64(x), yi = tf_floor_i64(y), zi = tf_floor_i64(z);
    int X = (int)(xi & 255), Y = (int)(yi & 255), Z = (int)(zi & 255);
    double fx = x - (double)xi, fy = y - (double)yi, fz = z - (double)zi;
    double u = tf_fade(fx), v = tf_fade(fy), w = tf_fade(fz);
    const uint16_t *p = nz->perm;
    /* Every index below is at most 255 + 255 + 1 = 511. */
    int A = p[X] + Y, AA = p[A] + Z, AB = p[A + 1] + Z;
    int B = p[X + 1] + Y, BA = p[B] + Z, BB = p[B + 1] + Z;
    double x1 = fx - 1.0, y1 = fy - 1.0, z1 = fz - 1.0;
    double n00 = lerp(u, grad3_dot(p[AA], fx, fy, fz), grad3_dot(p[BA], x1, fy, fz));
    double n10 = lerp(u, grad3_dot(p[AB], fx, y1, fz), grad3_dot(p[BB], x1, y1, fz));
    double n01 = lerp(u, grad3_dot(p[AA + 1], fx, fy, z1), grad3_dot(p[BA + 1], x1, fy, z1));
    double n11 = lerp(u, grad3_dot(p[AB + 1], fx, y1, z1), grad3_dot(p[BB + 1], x1, y1, z1));
    return lerp(w, lerp(v, n00, n10), lerp(v, n01, n11)) * TF_NOISE3_SCALE;
}

double tf_fbm2(const tf_noise *nz, double x, double y, double H, double lacunarity, double octaves)
{
    tf_octaves o;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octaves_plan(&o, H, lacunarity, octaves);
    tf_octave_axes(&o, y, axes);
    return tf_fbm2_axes(nz, &o, x, axes);
}

double tf_fbm2_gradient(const tf_noise *nz, double x, double y, double H, double lacunarity,
                        double octaves, double *gx, double *gy)
{
    tf_octaves o;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    tf_octaves_plan(&o, H, lacunarity, octaves);
    tf_octave_axes(&o, y, axes);
    return tf_fbm2_gradient_axes(nz, &o, x, axes, gx, gy);
}

double tf_fbm3(const tf_noise *nz, double x, double y, double z, double H, double lacunarity,
               double octaves)
{
    tf_octaves o;
    tf_octaves_plan(&o, H, lacunarity, octaves);
    double result = 0.0;
    for (int i = 0; i < o.count; i++) {
        result += o.amp[i] * tf_noise3(nz, x, y, z);
        x *= lacunarity;
        y *= lacunarity;
        z *= lacunarity;
    }
    return result;
}
