/* packet_shade.cl: lattice_sample8, the packet twin of terrafarm.cl's lattice_sample: the
 * camera ray of each active lane's lattice point, traced and shaded.
 *
 * FALLBACK: for now each active lane runs the scalar lattice_sample; the SIMD shading replaces
 * this body without changing its interface. */

/* Samples at lattice points (X, Y) of the active lanes: out[0..4] get r, g, b, a and distance
 * per lane (idle lanes: undefined); *shadow_rays[l] grows by the shadow rays lane l cast. */
void lattice_sample8(const world *w, ulong jitter_key, lv X, lv Y, lv mask, float8 out[5],
                     iv *shadow_rays)
{
    for (int l = 0; l < TF_LANES; l++) {
        if (!mask[l])
            continue;
        float s[TF_CL_SAMPLE_FLOATS];
        uint rays = 0;
        lattice_sample(w, jitter_key, X[l], Y[l], s, &rays);
        for (int k = 0; k < 5; k++)
            out[k][l] = s[k];
        (*shadow_rays)[l] += (int)rays;
    }
}
