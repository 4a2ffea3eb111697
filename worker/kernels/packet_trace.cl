/* packet_trace.cl: trace8 and occluded8, the packet twins of terrafarm.cl's trace and occluded.
 *
 * FALLBACK: for now each active lane runs the scalar trace; the SIMD walk of the max/min grids
 * replaces this file's bodies without changing its interface. */

/* First hit of each active lane's ray o + t d, t in (tmin, tmax): returns the lanes that hit,
 * with their hits in *hit (lanes that miss or are idle: *hit undefined there). */
lv trace8(const world *w, v3p o, v3p d, dv tmin, dv tmax, lv mask, hitp *hit)
{
    lv found = (lv)(0);
    for (int l = 0; l < TF_LANES; l++) {
        hit_t h;
        if (mask[l] && trace(w, v3p_lane(o, l), v3p_lane(d, l), tmin[l], tmax[l], &h)) {
            found[l] = -1;
            hit->t[l] = h.t;
            v3p_set_lane(&hit->p, l, h.p);
            v3p_set_lane(&hit->n, l, h.n);
            hit->ci[l] = h.ci;
            hit->cj[l] = h.cj;
        }
    }
    return found;
}

/* The active lanes whose ray meets the terrain in (tmin, tmax). */
lv occluded8(const world *w, v3p o, v3p d, dv tmin, dv tmax, lv mask)
{
    lv blocked = (lv)(0);
    for (int l = 0; l < TF_LANES; l++)
        if (mask[l] && occluded(w, v3p_lane(o, l), v3p_lane(d, l), tmin[l], tmax[l]))
            blocked[l] = -1;
    return blocked;
}
