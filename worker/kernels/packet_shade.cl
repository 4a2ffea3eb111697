/* packet_shade.cl: lattice_samples -- render.c's lattice samples for a batch of up to 128
 * lattice points: their camera rays, walked as one stream (walk_stream, packet_trace.cl), and
 * shaded in SIMD eight at a time, one sample per lane of the dv / lv / iv types of packet.cl,
 * with all their shadow rays walked as a second stream.
 *
 * The formulas are the C renderer's own (common/render/sample_math.h and
 * common/terrain/noise_kernel.h, compiled here on packets); this file holds their packet
 * schedule and what reads memory: the texture octave loops (fbm_with_gradient8,
 * snow_line_at8), the permutation and gradient lookups, the height
 * reads of the vertex normals, and the shading split around the batch's shadow walk.  Each
 * function NAME8 left here is the packet form of NAME in common/render/shade.c or render.c.
 * The one rule, on which the bit-identity of the OpenCL and C backends rests:
 *
 *   In every active lane, a packet function performs exactly the floating-point operations of
 *   its C counterpart, in the same order, on the same operands.
 *
 * So: FP contraction stays off (terrafarm.cl's pragma), no fma / mad / native_ / half_
 * functions, no reassociation (a scalar a * b * c stays (a * b) * c, a constant difference
 * like (b.x - a.x) of v3_lerp stays a separate subtraction).  The vector built-ins used (sqrt,
 * exp, expm1, log2, acos, cos, sin, fabs, fmin) compute per lane the function the scalar
 * built-in computes; bench_opencl's "bit-identical pixels" line is the check.
 *
 * How the scalar control flow becomes lanes:
 *   - A branch becomes a lane mask (lv: -1 active, 0 idle): both sides are evaluated and merged
 *     with select() (TF_SEL in the shared headers).  A side no active lane needs is skipped
 *     altogether with `if (any_lane(mask))` (TF_ANY)
 *     -- that is where the time is saved: the terrain, water and sky shaders, the bump fBm, the
 *     snow-line fBm and the shadow rays run only for packets in which some lane needs them.
 *   - A loop whose trip count differs per lane (the fBm octaves, which follow each sample's
 *     distance) runs to the largest count over the active lanes; a lane adds an octave to its
 *     sums only while the octave is one of its own, so each lane's sums are the scalar ones.
 *   - Lookups are per-lane loads written out lane by lane (PoCL keeps a lane loop as a loop
 *     through memory) through indices that are in range for every lane, idle or not: heights
 *     through clamped vertex indices, the permutation through indices masked to 0..511.  The
 *     16-entry gradient table is computed from its constants instead (grad_x8).  Hit fields of
 *     rays walk_stream reports no hit for are zeroed beforehand, so nothing is read
 *     uninitialised.
 *   - Work may be shared between lanes' computations only where their inputs are equal, so
 *     the outputs are too.
 *   - A scalar counter (shadow_rays) becomes an iv, bumped by the lanes that cast a ray.
 *
 * Profile (perf on bench_opencl, default.scene): shading is about a fifth of the kernels'
 * time, the bump fBm the largest part of it; tracing (packet_trace.cl) is most of the rest. */

/* ---------------------------------------------------------------- small packet helpers */

/* The same mask as an iv (for select on int8 / float8). */
iv mask_i(lv m) { return convert_int8(m); }

/* The height field at clamped vertex (i, j) of each lane (height_sample). */
dv height_sample8(const world *w, iv i, iv j)
{
    i = select(i, (iv)(0), i < 0);
    i = select(i, (iv)(w->n - 1), i >= w->n);
    j = select(j, (iv)(0), j < 0);
    j = select(j, (iv)(w->n - 1), j >= w->n);
    lv k = vertex_index8(w, convert_long8(i), convert_long8(j));
    return gather_f(w->h, k, (lv)(-1));
}

/* ---------------------------------------------------------------- noise (noise_impl.h) */

/* tf_fade, tf_floor_split, the y axis (tf_noise_axis_of), the column line and the blend are
 * noise_kernel.h's; what is here is the lattice side: permutation loads and gradients per
 * lane, and the x axis split so that fbm_with_gradient8 can share lookups between lanes.
 * tf_floor_split is only called on lanes whose |x| < 2^52 matter; the callers zero the others
 * first so every conversion is in range. */

typedef tf_noise_axis noise_axis8;

/* p[k] per lane, k in 0..511 (the permutation has 512 entries); written out lane by lane,
 * which PoCL turns into straight loads (a lane loop stays a loop through memory). */
iv perm8(__global const ushort *p, iv k)
{
    k &= TF_NOISE_PERM - 1;
    return convert_int8((ushort8)(p[k.s0], p[k.s1], p[k.s2], p[k.s3], p[k.s4], p[k.s5],
                                  p[k.s6], p[k.s7]));
}

/* tf_grad2[g & 15][0] per lane, without a table lookup (a per-lane lookup is a loop through
 * memory on PoCL).  The table's x column is cos(g * 22.5 deg): the magnitude is 1, TF_C1,
 * TF_H1, TF_S1 or 0 for k = min(g & 7, 8 - (g & 7)) = 0..4, the sign negative for g in
 * 5..11.  The values are the table's constants (a negation is exact), and the two zeros
 * (g = 4, 12) stay +0 as in the table.  The y column, sin(g * 22.5 deg), is the x column at
 * g + 12.  All 512 g of the permutation's range checked against the table, bit for bit. */
dv grad_x8(iv g)
{
    iv m = g & 7;
    iv k = select(m, 8 - m, m > 4);
    iv g15 = g & 15;
    dv mag = select((dv)(1.0), (dv)(TF_C1), convert_long8(k == 1));
    mag = select(mag, (dv)(TF_H1), convert_long8(k == 2));
    mag = select(mag, (dv)(TF_S1), convert_long8(k == 3));
    mag = select(mag, (dv)(0.0), convert_long8(k == 4));
    return select(mag, -mag, convert_long8((g15 >= 5) & (g15 <= 11)));
}

dv grad_y8(iv g) { return grad_x8(g + 12); }

/* noise_column per lane, in two steps: the gradients at the column's two lattice corners,
 * which depend only on the column's p[xi & 255] (px) and the y lattice, and then the column's
 * line (and for the bump, its y derivative) from them. */
typedef struct column_grads8 { dv g0x, g0y, g1x, g1y; } column_grads8;

TF_INLINE column_grads8 column_grads8_at(__global const ushort *p, iv px, iv lattice)
{
    iv a = px + lattice;
    iv g0 = perm8(p, a), g1 = perm8(p, a + 1);
    column_grads8 g = {grad_x8(g0), grad_y8(g0), grad_x8(g1), grad_y8(g1)};
    return g;
}

/* The column line slope * (x - X) + intercept from its gradients and the y axis. */
typedef tf_noise_column column_line8;

TF_INLINE column_line8 column_line8_of(const column_grads8 *g, const noise_axis8 *ay)
{
    return tf_noise_column_line(g->g0x, g->g0y, g->g1x, g->g1y, ay->f0, ay->f1, ay->fade);
}

/* The column line's derivative along y (tf_noise_column_dy), dfade = tf_fade_slope(ay->f0). */
TF_INLINE column_line8 column_dy8_of(const column_grads8 *g, const noise_axis8 *ay, dv dfade)
{
    return tf_noise_column_dy(g->g0x, g->g0y, g->g1x, g->g1y, ay->f0, ay->f1, ay->fade, dfade);
}

/* noise2_axis's x side, which depends on x alone. */
typedef struct noise_xaxis8 {
    lv ok;     /* |x| < TF_NOISE_COORD_LIMIT */
    dv f, u;   /* fraction and its fade */
    iv xi;     /* the lattice column, & 255 */
    iv pl, pr; /* p[xi], p[(xi + 1) & 255]: the left and right columns */
} noise_xaxis8;

/* Everything but the permutation loads pl, pr. */
TF_INLINE noise_xaxis8 noise_xaxis_frac8(dv x)
{
    noise_xaxis8 a;
    a.ok = fabs(x) < TF_NOISE_COORD_LIMIT;
    lv xl = tf_floor_split(select((dv)(0.0), x, a.ok), &a.f);
    a.xi = convert_int8(xl & (TF_NOISE_LATTICE - 1));
    a.u = tf_fade(a.f);
    return a;
}

TF_INLINE noise_xaxis8 noise_xaxis_set8(__global const ushort *p, dv x)
{
    noise_xaxis8 a = noise_xaxis_frac8(x);
    a.pl = perm8(p, a.xi);
    a.pr = perm8(p, (a.xi + 1) & (TF_NOISE_LATTICE - 1));
    return a;
}

/* noise2_axis per lane from the x axis, the two column lines and the y axis's ok. */
TF_INLINE dv noise2_lines8(const noise_xaxis8 *ax, const column_line8 *left,
                           const column_line8 *right, lv ok_y)
{
    return select((dv)(0.0), tf_noise_blend_faded(ax->f, ax->u, *left, *right), ax->ok & ok_y);
}

/* noise2_axis per lane, from its two axes. */
TF_INLINE dv noise2_axes8(__global const ushort *p, const noise_xaxis8 *ax,
                           const noise_axis8 *ay)
{
    column_grads8 gl = column_grads8_at(p, ax->pl, ay->lattice);
    column_grads8 gr = column_grads8_at(p, ax->pr, ay->lattice);
    column_line8 left = column_line8_of(&gl, ay), right = column_line8_of(&gr, ay);
    return noise2_lines8(ax, &left, &right, ay->ok);
}

/* fbm_with_gradient per lane (tf_fbm2_gradient_axes, noise_impl.h), with per-lane octave
 * counts: the loop runs to the largest count over `mask`; a lane adds octave i only while
 * i < its own count.  Per octave one noise value and its exact gradient, from the two
 * column lines and their y derivatives. */
dv fbm_with_gradient8(const world *w, dv x, dv y, double scale, int amp_table, dv octaves,
                      double salt, lv mask, dv *gx, dv *gy)
{
    __global const double *amp = w->P + amp_table;
    __global const ushort *p = w->perm;
    dv qx = x / scale + salt, qy = y / scale - salt;
    octaves = select((dv)(1.0), octaves, octaves >= 1.0);
    octaves = select(octaves, (dv)(TF_CL_AMP_TABLE - 1), octaves > TF_CL_AMP_TABLE - 1);
    iv whole = convert_int8(octaves);
    dv remainder = octaves - convert_double8(whole);
    lv partial = remainder > 0.0;
    iv count = whole - mask_i(partial);
    /* the most octaves a lane of mask needs (0: none), as a vector maximum (a loop over the
     * lanes stored the mask to the stack at every turn: lane_bytes) */
    iv c = select((iv)(0), count, convert_int8(mask));
    int4 c4 = max(c.lo, c.hi);
    int2 c2 = max(c4.lo, c4.hi);
    int most = max(max(c2.x, c2.y), 0);
    dv f = 0.0, sx = 0.0, sy = 0.0;
    double frequency = 1.0;
    for (int i = 0; i < most; i++) {
        lv in = convert_long8(count > i);
        dv a = (dv)(amp[i]);
        a = select(a, a * remainder, partial & convert_long8(whole == i));
        noise_axis8 ay = tf_noise_axis_of(qy);
        noise_xaxis8 ax = noise_xaxis_set8(p, qx);
        dv dfade = tf_fade_slope(ay.f0);
        column_grads8 gl = column_grads8_at(p, ax.pl, ay.lattice);
        column_grads8 gr = column_grads8_at(p, ax.pr, ay.lattice);
        column_line8 left = column_line8_of(&gl, &ay), right = column_line8_of(&gr, &ay);
        column_line8 left_dy = column_dy8_of(&gl, &ay, dfade);
        column_line8 right_dy = column_dy8_of(&gr, &ay, dfade);
        dv dx, dy;
        dv n = tf_noise_blend_gradient(ax.f, ax.u, tf_fade_slope(ax.f), left, right, left_dy,
                                       right_dy, &dx, &dy);
        lv ok = in & ax.ok & ay.ok;
        dv weight = a * frequency;
        f = select(f, f + a * select((dv)(0.0), n, ax.ok & ay.ok), in);
        sx = select(sx, sx + weight * select((dv)(0.0), dx, ok), in);
        sy = select(sy, sy + weight * select((dv)(0.0), dy, ok), in);
        qx *= 2.0;
        qy *= 2.0;
        frequency *= 2.0;
    }
    *gx = sx;
    *gy = sy;
    return f;
}

/* ---------------------------------------------------------------- shading (shade.c) */

v3p vertex_normal8(const world *w, iv i, iv j)
{
    const int n = w->n;
    iv hi_i = select(i, i + 1, i + 1 < n), lo_i = select(i, i - 1, i > 0);
    iv hi_j = select(j, j + 1, j + 1 < n), lo_j = select(j, j - 1, j > 0);
    dv span_x = convert_double8(hi_i - lo_i) * w->cell;
    dv span_y = convert_double8(hi_j - lo_j) * w->cell;
    return tf_vertex_normal_of(height_sample8(w, i - 1, j), height_sample8(w, i + 1, j),
                               height_sample8(w, i, j - 1), height_sample8(w, i, j + 1), span_x,
                               span_y);
}

/* hit_triangle_at: the triangle of the cell that holds p picks its side vertex (ci+1, cj) or
 * (ci, cj+1) per lane; both cases are the same sums with the weights and the side vertex
 * chosen per lane. */
typedef struct hit_triangle8 {
    iv ci, cj, si, sj;
    v3p n00, nside, n11;
    dv fx, fy;
} hit_triangle8;

hit_triangle8 hit_triangle8_at(const world *w, iv ci, iv cj, v3p p)
{
    hit_triangle8 t;
    ci = select(select(ci, (iv)(w->cells - 1), ci >= w->cells), (iv)(0), ci < 0);
    cj = select(select(cj, (iv)(w->cells - 1), cj >= w->cells), (iv)(0), cj < 0);
    dv fx = p.x / w->cell - convert_double8(ci), fy = p.y / w->cell - convert_double8(cj);
    t.fx = tf_clamp01(fx);
    t.fy = tf_clamp01(fy);
    iv lower_i = mask_i(t.fx >= t.fy); /* side vertex (ci+1, cj) */
    t.ci = ci;
    t.cj = cj;
    t.si = select(ci, ci + 1, lower_i);
    t.sj = select(cj + 1, cj, lower_i);
    t.n00 = vertex_normal8(w, ci, cj);
    t.n11 = vertex_normal8(w, ci + 1, cj + 1);
    t.nside = vertex_normal8(w, t.si, t.sj);
    return t;
}

/* smooth_normal */
v3p smooth_normal8(const hit_triangle8 *t)
{
    return tf_smooth_normal_blend(t->n00, t->nside, t->n11, t->fx, t->fy);
}

/* vertex_at: sample (i, j) in the world */
v3p vertex_at8(const world *w, iv i, iv j)
{
    return v3p_make(convert_double8(i) * w->cell, convert_double8(j) * w->cell,
                    height_sample8(w, i, j));
}

/* smooth_shadow_origin */
v3p smooth_shadow_origin8(const world *w, const hit_triangle8 *t, v3p p)
{
    v3p v00 = vertex_at8(w, t->ci, t->cj), v11 = vertex_at8(w, t->ci + 1, t->cj + 1);
    return tf_smooth_shadow_origin(p, v00, t->n00, vertex_at8(w, t->si, t->sj), t->nside, v11,
                                   t->n11, t->fx, t->fy);
}

/* shade.c's tf_sky_color and tf_mist_apply per lane. */
v3p sky_color8(const world *w, v3p dir)
{
    return tf_sky_radiance(pvec(w, TFP_SKY_HORIZON), pvec(w, TFP_SKY_ZENITH),
                           pvec(w, TFP_SUN_DIR), pvec(w, TFP_SUN_LIGHT), dir);
}

v3p mist_apply8(const world *w, v3p c, v3p origin, v3p dir, dv len)
{
    if (!w->I[TFI_MIST_ENABLED] || w->P[TFP_MIST_DENSITY] <= 0)
        return c;
    dv tau = tf_mist_depth(w->P[TFP_MIST_DENSITY], w->P[TFP_MIST_K], w->I[TFI_MIST_HOMOG],
                           origin.z, dir.z, len);
    return tf_mist_blend(c, tau, pvec(w, TFP_MIST_EXT), pvec(w, TFP_MIST_COLOR));
}

/* sunlit's first half for the lanes of `mask`: the lanes that cast a shadow ray (sunlit's
 * occluded call), and where their rays start.  The rays are walked later, with the batch's. */
lv sunlit_cast8(const world *w, v3p p, v3p ng, lv mask, v3p *start)
{
    vec3 sun = pvec(w, TFP_SUN_DIR);
    if (sun.z <= -1.0)
        return (lv)(0);
    lv cast = mask & (v3p_dot(ng, v3p_splat(sun)) > 0.0);
    if (any_lane(cast))
        *start = v3p_select(*start, v3p_add(p, v3p_scale(ng, (dv)(w->P[TFP_SHADOW_LIFT]))), cast);
    return cast;
}

/* shade.c's snow_line_at per lane: the snow fBm's octaves summed only while they can still
 * move the albedo -- past the slope's cut (S1 there) and while tf_snow_line_matters with the
 * bound of the octaves to come (S2) -- each lane stopping where its C sample stops, the packet
 * when all have. */
dv snow_line_at8(const world *w, v3p p, dv slope, lv mask)
{
    const double line = w->P[TFP_SNOW_LINE], jitter = w->P[TFP_SNOW_JITTER];
    const double extent = w->P[TFP_EXTENT], band = w->P[TFP_BAND];
    lv on = mask & (tf_snow_slope_weight(w->P[TFP_ROCK_SLOPE], slope) != 0.0);
    if (!(jitter > 0) || !any_lane(on))
        return (dv)(line);
    __global const double *amp = w->P + TFP_AMP_H05;
    dv x = tf_snow_u(p.x, extent), y = tf_snow_v(p.y, extent), sum = 0.0;
    lv adding = on;
    for (int k = 0; k < TF_CL_SNOW_TERMS; k++) {
        adding &= tf_snow_line_matters(line + jitter * sum, jitter, w->P[TFP_SNOW_REST + k],
                                       band, p.z);
        if (!any_lane(adding))
            break;
        noise_axis8 ay = tf_noise_axis_of(y);
        noise_xaxis8 ax = noise_xaxis_set8(w->perm, x);
        sum = select(sum, sum + amp[k] * noise2_axes8(w->perm, &ax, &ay), adding);
        x *= 2.0;
        y *= 2.0;
    }
    return select((dv)(line), line + jitter * sum, on);
}

/* shade.c's tf_shade_albedo. */
v3p terrain_albedo8(const world *w, v3p p, v3p n, dv variation, lv mask)
{
    dv slope = tf_slope_deg(n.z);
    return tf_terrain_albedo(w->P[TFP_TREE_LINE], w->P[TFP_SEA_LEVEL], w->P[TFP_ROCK_SLOPE],
                             w->P[TFP_BAND], p.z, slope, snow_line_at8(w, p, slope, mask),
                             variation);
}

/* ---------------------------------------------------------------- shading around the shadows
 *
 * The shadow ray cuts shade_terrain and shade_water in two.  The first halves (NAME_before8)
 * do everything up to the sunlit test and say which lanes cast a shadow ray from where; the
 * shadow rays of the whole batch are then walked as one stream (walk_stream); the second half
 * (shading_finish8) adds the sun where the ray got through.  Each lane's operations and their
 * order are shade_terrain's and shade_water's: only the time between the halves changes. */

/* What a terrain or water lane carries across the shadow walk. */
typedef struct shading8 {
    v3p albedo;   /* terrain */
    v3p light;    /* the light before the sun's share */
    dv sun_gain;  /* the sun's share where lit: cos_sun (terrain), sun.z (water) */
    v3p refl_sky; /* water: the sky the ripples reflect */
    dv fresnel;   /* water */
    v3p start;    /* the shadow ray's origin */
    lv cast;      /* the lanes that cast a shadow ray */
} shading8;

/* shade_terrain up to its sunlit call, for the lanes of `mask` (their ray hit the terrain). */
void terrain_before8(const world *w, const hitp *hit, lv mask, shading8 *sh)
{
    hit_triangle8 tri = hit_triangle8_at(w, hit->ci, hit->cj, hit->p);
    v3p n = smooth_normal8(&tri);
    v3p nb = n;
    dv variation = 0.0;
    dv octaves = tf_visible_octaves(w->P[TFP_PIXEL_ANGLE], w->P[TFP_BUMP_SCALE], hit->t,
                                    TF_BUMP_OCTAVES);
    if (w->I[TFI_TEXTURED] && w->P[TFP_BUMP] > 0) {
        lv bumped = mask & (octaves > 0.0);
        if (any_lane(bumped)) {
            dv gx, gy;
            dv var = fbm_with_gradient8(w, hit->p.x, hit->p.y, w->P[TFP_BUMP_SCALE],
                                        TFP_AMP_H08, octaves, 0.0, bumped, &gx, &gy);
            v3p nbump = tf_bump_normal(n, w->P[TFP_BUMP], gx, gy);
            variation = select(variation, var, bumped);
            nb = v3p_select(nb, nbump, bumped);
        }
    }
    v3p albedo = terrain_albedo8(w, hit->p, n, variation, mask);
    dv cos_sun = v3p_dot(nb, v3p_splat(pvec(w, TFP_SUN_DIR)));
    v3p light = tf_sky_light_on(pvec(w, TFP_SKY_LIGHT), nb.z);
    sh->albedo = v3p_select(sh->albedo, albedo, mask);
    sh->light = v3p_select(sh->light, light, mask);
    sh->sun_gain = select(sh->sun_gain, cos_sun, mask);
    /* terrain_sunlit: flat, from the hit triangle itself; smooth, from the smooth surface */
    v3p from = hit->p, facing = hit->n;
    if (w->I[TFI_SMOOTH]) {
        from = smooth_shadow_origin8(w, &tri, hit->p);
        facing = n;
    }
    sh->cast |= sunlit_cast8(w, from, facing, mask & (cos_sun > 0.0), &sh->start);
}

/* shade_water up to its sunlit call, for the lanes of `mask` (their ray reached the sea). */
void water_before8(const world *w, v3p p, v3p dir, dv dist, lv mask, shading8 *sh)
{
    v3p n = v3p_splat(v3(0, 0, 1));
    dv octaves = tf_visible_octaves(w->P[TFP_PIXEL_ANGLE], w->P[TFP_RIPPLE_SCALE], dist,
                                    TF_RIPPLE_OCTAVES);
    if (w->I[TFI_TEXTURED] && w->P[TFP_BUMP] > 0) {
        lv rippled = mask & (octaves > 0.0);
        if (any_lane(rippled)) {
            dv gx, gy;
            fbm_with_gradient8(w, p.x, p.y, w->P[TFP_RIPPLE_SCALE], TFP_AMP_H05, octaves,
                               TF_RIPPLE_SALT, rippled, &gx, &gy);
            n = v3p_select(n, tf_ripple_normal(gx, gy), rippled);
        }
    }
    v3p refl;
    dv fresnel = tf_water_surface(dir, n, &refl);
    vec3 sun = pvec(w, TFP_SUN_DIR);
    sh->light = v3p_select(sh->light, v3p_splat(pvec(w, TFP_SKY_LIGHT)), mask);
    sh->sun_gain = select(sh->sun_gain, (dv)(sun.z), mask);
    sh->refl_sky = v3p_select(sh->refl_sky, sky_color8(w, v3p_norm(refl)), mask);
    sh->fresnel = select(sh->fresnel, fresnel, mask);
    if (sun.z > 0)
        sh->cast |= sunlit_cast8(w, p, v3p_splat(v3(0, 0, 1)), mask, &sh->start);
}

/* The second halves of shade_terrain (terrain lanes) and shade_water (water lanes): the
 * colour, the sun added where `lit`. */
v3p shading_finish8(const world *w, const shading8 *sh, lv terrain, lv water, lv lit)
{
    v3p light = v3p_select(sh->light,
                           v3p_add(sh->light, v3p_scale(v3p_splat(pvec(w, TFP_SUN_LIGHT)),
                                                        sh->sun_gain)),
                           lit);
    v3p c = v3p_splat(v3(0, 0, 0));
    if (any_lane(terrain))
        c = v3p_select(c, v3p_mul(sh->albedo, light), terrain);
    if (any_lane(water)) {
        c = v3p_select(c, tf_water_color(light, sh->refl_sky, sh->fresnel), water);
    }
    return c;
}

/* ---------------------------------------------------------------- the lattice (render.c) */

/* The camera ray directions of lattice points (X, Y) (render.c's lattice_sample and
 * camera.c's tf_camera_dir). */
v3p lattice_dir8(const world *w, ulong jitter_key, lv X, lv Y)
{
    dv x, y;
    tf_lattice_position(jitter_key, (double)w->I[TFI_LATTICE], X, Y, &x, &y);
    return tf_camera_ray(&w->cam, x, y);
}

/* The sun's strips' frame, as the host put it in P[] / I[] (tf_cl_params.h). */
tf_sun_frame sun_frame(const world *w)
{
    __global const double *v = w->P + TFP_SUN_FRAME;
    tf_sun_frame f = {v[0], v[1], v[2],  v[3],  v[4],  v[5],  v[6],  v[7],
                      v[8], v[9], v[10], v[11], v[12], v[13], v[14],
                      w->I[TFI_SUN_STRIPS], w->I[TFI_SUN_BINS], w->I[TFI_SUN_LOOK],
                      w->I[TFI_SUN_N]};
    return f;
}

/* The samples at n <= TF_STREAM lattice points: sample k is lane k % 8 of packet k / 8 of
 * X[], Y[], out[][0..4] (r, g, b, a, distance) and shadow_rays[] (which grows by the shadow
 * rays each sample cast).  lattice_sample + shade_ray per sample, with all the camera rays
 * walked as one stream and all the shadow rays as another.  lows, fars (or NULL): the records
 * of lower camera rays that help sample k's, the second where the first cannot (walk_stream);
 * records (or NULL): where sample k's camera ray leaves its own. */
void lattice_samples(const world *w, ulong jitter_key, const lv X[], const lv Y[], int n,
                     const ray_clears *lows, const ray_clears *fars, float8 out[][5],
                     iv shadow_rays[], ray_clears *records)
{
    const int np = (n + TF_LANES - 1) / TF_LANES;
    const v3p origin = v3p_splat(pvec(w, TFP_CAM_POS));
    const double sea = w->P[TFP_SEA_LEVEL];
    const vec3 sun = pvec(w, TFP_SUN_DIR);
    const tf_sun_frame strips = sun_frame(w);
    const v3p zero = v3p_splat(v3(0, 0, 0));
    lv mask[TF_STREAM_PACKETS], lit[TF_STREAM_PACKETS];
    ray_stream cam; /* d: the directions, tmax: the water distances (TF_FAR_AWAY: none) */
    cam.n = n;
    cam.one_dir = 0;
    const lv lane = (lv)(0, 1, 2, 3, 4, 5, 6, 7);
    for (int p = 0; p < np; p++) {
        mask[p] = lane < (lv)(n - p * TF_LANES);
        v3p dir = lattice_dir8(w, jitter_key, X[p], Y[p]);
        dv t_water = (dv)(TF_FAR_AWAY);
        t_water = select(t_water, (sea - origin.z) / dir.z, (dir.z < 0.0) & (origin.z > sea));
        cam.o[p] = origin;
        cam.d[p] = dir;
        cam.tmin[p] = (dv)(0.0);
        cam.tmax[p] = t_water;
    }
    lv found[TF_STREAM_PACKETS];
    hitp hit[TF_STREAM_PACKETS];
    for (int p = 0; p < np; p++) {
        hit[p].t = (dv)(0.0);
        hit[p].p = hit[p].n = zero;
        hit[p].ci = hit[p].cj = (iv)(0);
    }
    walk_stream(w, &cam, lows, fars, found, hit, records);

    shading8 sh[TF_STREAM_PACKETS];
    lv terrain[TF_STREAM_PACKETS], water[TF_STREAM_PACKETS];
    ray_stream shadow;
    uchar shadow_of[TF_STREAM]; /* the sample that cast shadow ray m */
    /* shadow ray m's start and tmax, gathered a ray at a time and made packets after (a lane
     * put into a vector in place stores and reloads the whole vector) */
    double start_x[TF_STREAM], start_y[TF_STREAM], start_z[TF_STREAM], until[TF_STREAM];
    shadow.n = 0;
    for (int p = 0; p < np; p++) {
        terrain[p] = mask[p] & found[p];
        water[p] = mask[p] & ~terrain[p] & (cam.tmax[p] < TF_FAR_AWAY);
        shading8 *s = &sh[p];
        s->albedo = s->light = s->refl_sky = s->start = zero;
        s->sun_gain = s->fresnel = (dv)(0.0);
        s->cast = (lv)(0);
        if (any_lane(terrain[p]))
            terrain_before8(w, &hit[p], terrain[p], s);
        if (any_lane(water[p])) {
            v3p pw = v3p_add(origin, v3p_scale(cam.d[p], cam.tmax[p]));
            water_before8(w, pw, cam.d[p], cam.tmax[p], water[p], s);
        }
        shadow_rays[p] -= mask_i(s->cast);
        lit[p] = (lv)(0);
        const ulong casts = lane_bytes(s->cast);
        for (int l = 0; l < TF_LANES; l++) {
            if (!((casts >> (8 * l)) & 1))
                continue;
            /* what the sun's strips prove (shade.c tf_shadow_strips): occluded, no walk; or
             * clear past t, the walk ends there */
            double t;
            const int said = tf_sun_strips_say(&strips, w->strips, w->h, s->start.x[l],
                                               s->start.y[l], s->start.z[l], 0, &t);
            if (said == TF_SUN_UNDER)
                continue;
            const int m = shadow.n++;
            shadow_of[m] = (uchar)(p * TF_LANES + l);
            start_x[m] = s->start.x[l];
            start_y[m] = s->start.y[l];
            start_z[m] = s->start.z[l];
            until[m] = said == TF_SUN_CLEAR_AFTER ? t : TF_FAR_AWAY;
        }
    }
    lv blocked[TF_STREAM_PACKETS];
    if (shadow.n > 0) {
        for (int m = shadow.n; m % TF_LANES; m++) /* the last packet's lanes past the end */
            start_x[m] = start_y[m] = start_z[m] = until[m] = 0.0;
        for (int q = 0; q * TF_LANES < shadow.n; q++) {
            shadow.o[q] = v3p_make(vload8(q, start_x), vload8(q, start_y), vload8(q, start_z));
            shadow.d[q] = v3p_splat(sun);
            shadow.tmin[q] = (dv)(0.0);
            shadow.tmax[q] = vload8(q, until);
        }
        shadow.one_dir = 1; /* every shadow ray's direction is the sun's */
        walk_stream(w, &shadow, NULL, NULL, blocked, NULL, NULL);
        long lit_of[TF_STREAM]; /* sample k: lit (-1) or not */
        for (int k = 0; k < np * TF_LANES; k++)
            lit_of[k] = 0;
        for (int m = 0; m < shadow.n; m++)
            lit_of[shadow_of[m]] = blocked[m / TF_LANES][m % TF_LANES] ? 0 : -1;
        for (int p = 0; p < np; p++)
            lit[p] = vload8(p, lit_of);
    }

    for (int p = 0; p < np; p++) {
        lv sky = mask[p] & ~terrain[p] & ~water[p];
        v3p c = shading_finish8(w, &sh[p], terrain[p], water[p], lit[p]);
        dv dist = (dv)(INFINITY); /* the sky lanes' mist length */
        dist = select(dist, hit[p].t, terrain[p]);
        dist = select(dist, cam.tmax[p], water[p]);
        if (any_lane(sky))
            c = v3p_select(c, sky_color8(w, cam.d[p]), sky);
        c = mist_apply8(w, c, origin, cam.d[p], dist);
        iv sky_i = mask_i(sky);
        out[p][0] = convert_float8(c.x);
        out[p][1] = convert_float8(c.y);
        out[p][2] = convert_float8(c.z);
        out[p][3] = select((float8)(1.0f), (float8)(0.0f), sky_i);
        out[p][4] = select(convert_float8(dist), (float8)(TF_SKY_DIST), sky_i);
    }
}
