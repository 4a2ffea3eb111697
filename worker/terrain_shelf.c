/* terrain_shelf.c: see terrain_shelf.h. */
#include "worker/terrain_shelf.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "render/sun_strips.h"

#define SHELF_MAX 16

typedef struct shelf_entry {
    char key[65];
    tf_heightfield *hf;
    size_t bytes;
    uint64_t used; /* larger: more recent */
} shelf_entry;

struct tf_terrain_shelf {
    size_t budget, total;
    uint64_t clock;
    int n;
    shelf_entry e[SHELF_MAX];
};

size_t tf_heightfield_bytes(const tf_heightfield *hf)
{
    size_t n2 = (size_t)hf->n * (size_t)hf->n, grids = 0;
    for (int l = 0; hf->maxgrid && l < hf->levels; l++) {
        size_t side = (size_t)hf->cells >> l;
        grids += 2 * side * side;
    }
    int maps = (hf->water != NULL) + (hf->silt != NULL) + (hf->flow != NULL);
    return sizeof *hf + (n2 * (size_t)(1 + maps) + grids) * sizeof(float) +
           tf_sun_strips_kept_bytes(hf);
}

tf_terrain_shelf *tf_terrain_shelf_new(size_t budget_bytes)
{
    tf_terrain_shelf *sh = calloc(1, sizeof *sh);
    if (sh)
        sh->budget = budget_bytes;
    return sh;
}

static void drop(tf_terrain_shelf *sh, int i)
{
    tf_heightfield_free(sh->e[i].hf);
    sh->total -= sh->e[i].bytes;
    sh->e[i] = sh->e[--sh->n];
}

void tf_terrain_shelf_free(tf_terrain_shelf *sh)
{
    while (sh && sh->n)
        drop(sh, 0);
    free(sh);
}

const tf_heightfield *tf_terrain_shelf_get(tf_terrain_shelf *sh, const char *key)
{
    for (int i = 0; i < sh->n; i++)
        if (!strcmp(sh->e[i].key, key)) {
            sh->e[i].used = ++sh->clock;
            return sh->e[i].hf;
        }
    return NULL;
}

static int least_recent(const tf_terrain_shelf *sh)
{
    int k = 0;
    for (int i = 1; i < sh->n; i++)
        if (sh->e[i].used < sh->e[k].used)
            k = i;
    return k;
}

void tf_terrain_shelf_put(tf_terrain_shelf *sh, const char *key, tf_heightfield *hf)
{
    size_t bytes = tf_heightfield_bytes(hf);
    for (int i = 0; i < sh->n; i++) /* a key put again: the new terrain replaces the old */
        if (!strncmp(sh->e[i].key, key, sizeof sh->e[i].key - 1)) {
            if (sh->e[i].hf == hf) { /* the same one: only its use is new */
                sh->e[i].used = ++sh->clock;
                return;
            }
            drop(sh, i);
            break;
        }
    while (sh->n && (sh->n == SHELF_MAX || sh->total + bytes > sh->budget))
        drop(sh, least_recent(sh));
    shelf_entry *e = &sh->e[sh->n++];
    memset(e->key, 0, sizeof e->key);
    strncpy(e->key, key, sizeof e->key - 1);
    e->hf = hf;
    e->bytes = bytes;
    e->used = ++sh->clock;
    sh->total += bytes;
}

int tf_terrain_shelf_keys(const tf_terrain_shelf *sh, const char **keys, int max)
{
    int order[SHELF_MAX], n = 0;
    for (int i = 0; i < sh->n; i++)
        order[n++] = i;
    for (int a = 0; a < n; a++) /* most recent first: a tiny selection sort */
        for (int b = a + 1; b < n; b++)
            if (sh->e[order[b]].used > sh->e[order[a]].used) {
                int t = order[a];
                order[a] = order[b];
                order[b] = t;
            }
    int k = n < max ? n : max;
    for (int i = 0; i < k; i++)
        keys[i] = sh->e[order[i]].key;
    return k;
}
