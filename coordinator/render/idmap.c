/* idmap.c: see idmap.h. */
#include "coordinator/render/idmap.h"

#include <stdlib.h>

static size_t slot_for(uint64_t key, size_t cap)
{
    key ^= key >> 33; /* splitmix-style finaliser: connection ids are consecutive */
    key *= 0xff51afd7ed558ccdull;
    key ^= key >> 33;
    return (size_t)key & (cap - 1);
}

static int grow(tf_idmap *m)
{
    size_t cap = m->cap ? 2 * m->cap : 64;
    uint64_t *keys = calloc(cap, sizeof *keys);
    int64_t *vals = calloc(cap, sizeof *vals);
    if (!keys || !vals) {
        free(keys);
        free(vals);
        return -1;
    }
    for (size_t i = 0; i < m->cap; i++) {
        if (!m->keys[i])
            continue;
        size_t j = slot_for(m->keys[i], cap);
        while (keys[j])
            j = (j + 1) & (cap - 1);
        keys[j] = m->keys[i];
        vals[j] = m->vals[i];
    }
    free(m->keys);
    free(m->vals);
    m->keys = keys;
    m->vals = vals;
    m->cap = cap;
    return 0;
}

int tf_idmap_put(tf_idmap *m, uint64_t key, int64_t val)
{
    if (!key)
        return -1;
    if (2 * (m->n + 1) > m->cap && grow(m))
        return -1;
    size_t i = slot_for(key, m->cap);
    while (m->keys[i] && m->keys[i] != key)
        i = (i + 1) & (m->cap - 1);
    if (!m->keys[i]) {
        m->keys[i] = key;
        m->n++;
    }
    m->vals[i] = val;
    return 0;
}

int tf_idmap_get(const tf_idmap *m, uint64_t key, int64_t *val)
{
    if (!key || !m->cap)
        return 0;
    for (size_t i = slot_for(key, m->cap); m->keys[i]; i = (i + 1) & (m->cap - 1))
        if (m->keys[i] == key) {
            *val = m->vals[i];
            return 1;
        }
    return 0;
}

void tf_idmap_del(tf_idmap *m, uint64_t key)
{
    if (!key || !m->cap)
        return;
    size_t mask = m->cap - 1, i = slot_for(key, m->cap);
    while (m->keys[i] && m->keys[i] != key)
        i = (i + 1) & mask;
    if (!m->keys[i])
        return;
    /* Backward shift: move later entries of the probe run into the hole when their home slot
     * does not lie (cyclically) between the hole and them. */
    for (size_t j = (i + 1) & mask; m->keys[j]; j = (j + 1) & mask) {
        size_t home = slot_for(m->keys[j], m->cap);
        if (((j - home) & mask) >= ((j - i) & mask)) {
            m->keys[i] = m->keys[j];
            m->vals[i] = m->vals[j];
            i = j;
        }
    }
    m->keys[i] = 0;
    m->n--;
}

void tf_idmap_free(tf_idmap *m)
{
    free(m->keys);
    free(m->vals);
    m->keys = NULL;
    m->vals = NULL;
    m->cap = m->n = 0;
}
