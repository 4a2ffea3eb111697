/* erosion_role.c: the erosion worker role's rules and its ownership guard (erosion_role.h). */
#include "coordinator/erosion/erosion_role.h"

#include <stdio.h>
#include <string.h>

#include "farmproto.h"

void tf_erosion_owners_take(tf_erosion_owners *o, uint64_t conn, const tf_tuple *patch)
{
    int64_t p;
    const char *name = tf_tuple_name(patch);
    if (name && !strcmp(name, "erode_patch") && patch->nfields == 3 &&
        tf_tuple_get_int(patch, 2, &p) == 0 && p >= 0 && p < o->patches)
        o->conn[p] = conn;
}

int tf_erosion_owners_patch(const tf_erosion_owners *o, uint64_t conn)
{
    for (int p = 0; p < o->patches; p++)
        if (o->conn[p] == conn)
            return p;
    return -1;
}

/* A tuple about patch field 2 is allowed only to the connection that took that patch. */
static ts_cap_verdict own_patch(void *ctx, uint64_t conn, int op, int blocking,
                                const tf_tuple *t, char *why, size_t whylen)
{
    (void)op;
    (void)blocking;
    const tf_erosion_owners *o = ctx;
    int64_t p;
    int mine = tf_erosion_owners_patch(o, conn);
    if (tf_tuple_get_int(t, 2, &p) != 0)
        p = -1;
    if (mine < 0 || p != mine) {
        char held[32];
        snprintf(held, sizeof held, mine < 0 ? "no patch" : "patch %d", mine);
        snprintf(why, whylen, "%s of patch %lld from a worker holding %s",
                 tf_tuple_name(t) ? tf_tuple_name(t) : "?", (long long)p, held);
        return TS_CAP_REFUSE;
    }
    return TS_CAP_ALLOW;
}

static const ts_cap_rule rules[] = {
    {TS_CAP_RD, TF_TAG_SCENE, TF_SCENE_FIELDS, 0, NULL},
    {TS_CAP_RD, "heightmap", 4, 0, NULL},
    {TS_CAP_RD, "heightmap_chunk", 3, 0, NULL},
    {TS_CAP_RD, "erode_plan", 7, 0, NULL},
    {TS_CAP_IN, "erode_patch", 3, 1, NULL},
    {TS_CAP_RD, "erode_edge", 6, 0, NULL},
    {TS_CAP_OUT | TS_CAP_IN, "erode_edge", 6, 0, own_patch},
    {TS_CAP_OUT, "erode_final", 6, 0, own_patch},
    {TS_CAP_OUT, "erode_tally", 7, 1, own_patch},
    {TS_CAP_OUT, "erode_failed", 4, 1, own_patch},
};

void tf_erosion_role_init(ts_role *role, tf_erosion_owners *owners, size_t max_tuple_bytes)
{
    role->name = "erosion worker";
    role->rules = rules;
    role->nrules = (int)(sizeof rules / sizeof rules[0]);
    role->guard_ctx = owners;
    role->max_tuple_bytes = max_tuple_bytes;
}
