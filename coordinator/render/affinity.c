/* affinity.c: horizontal-extent affinity, the ranges and the ranks (see affinity.h).  The
 * workers are kept sorted by id; worker k of n owns columns [k*width/n, (k+1)*width/n). */
#include "coordinator/render/affinity.h"

#include <stdlib.h>
#include <string.h>

struct tf_affinity {
    int width;
    int n, cap;
    int64_t *ids; /* sorted, distinct */
};

tf_affinity *tf_affinity_new(int width)
{
    tf_affinity *a = calloc(1, sizeof *a);
    if (a)
        a->width = width > 0 ? width : 1;
    return a;
}

void tf_affinity_free(tf_affinity *a)
{
    if (!a)
        return;
    free(a->ids);
    free(a);
}

/* The index of worker among the sorted ids, or where it would go (*found: whether it is). */
static int position(const tf_affinity *a, int64_t worker, int *found)
{
    int lo = 0, hi = a->n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (a->ids[mid] < worker)
            lo = mid + 1;
        else
            hi = mid;
    }
    *found = lo < a->n && a->ids[lo] == worker;
    return lo;
}

int tf_affinity_join(tf_affinity *a, int64_t worker)
{
    int found, k = position(a, worker, &found);
    if (found)
        return 0;
    if (a->n == a->cap) {
        int cap = a->cap ? 2 * a->cap : 16;
        int64_t *ids = realloc(a->ids, (size_t)cap * sizeof *ids);
        if (!ids)
            return -1;
        a->ids = ids;
        a->cap = cap;
    }
    memmove(a->ids + k + 1, a->ids + k, (size_t)(a->n - k) * sizeof *a->ids);
    a->ids[k] = worker;
    a->n++;
    return 0;
}

void tf_affinity_leave(tf_affinity *a, int64_t worker)
{
    int found, k = position(a, worker, &found);
    if (!found)
        return;
    memmove(a->ids + k, a->ids + k + 1, (size_t)(a->n - k - 1) * sizeof *a->ids);
    a->n--;
}

int tf_affinity_workers(const tf_affinity *a) { return a->n; }

/* The first column of range k (k = n: the width). */
static int range_start(const tf_affinity *a, int k)
{
    return (int)((int64_t)k * a->width / a->n);
}

int tf_affinity_range(const tf_affinity *a, int64_t worker, int *x0, int *x1)
{
    int found, k = position(a, worker, &found);
    if (!found)
        return -1;
    *x0 = range_start(a, k);
    *x1 = range_start(a, k + 1);
    return 0;
}

/* The range holding column x (n >= 1): the last one starting at or before it. */
static int range_of_column(const tf_affinity *a, int x)
{
    if (x < 0)
        x = 0;
    if (x >= a->width)
        x = a->width - 1;
    int k = (int)((int64_t)x * a->n / a->width);
    while (k + 1 < a->n && range_start(a, k + 1) <= x)
        k++;
    while (k > 0 && range_start(a, k) > x)
        k--;
    return k;
}

int tf_affinity_range_of(const tf_affinity *a, tf_rect r)
{
    return a->n > 0 ? range_of_column(a, r.x + r.w / 2) : -1;
}

tf_affinity_choice tf_affinity_choice_of(const tf_affinity *a, int64_t worker, tf_rect r)
{
    int found, k = position(a, worker, &found);
    if (!found)
        return TF_AFFINITY_NONE;
    int j = tf_affinity_range_of(a, r);
    if (j == k)
        return TF_AFFINITY_FIRST;
    return j == k - 1 || j == k + 1 ? TF_AFFINITY_SECOND : TF_AFFINITY_ELSEWHERE;
}

uint64_t tf_affinity_rank(const tf_affinity *a, int64_t worker, tf_rect r, int64_t id)
{
    tf_affinity_choice c = tf_affinity_choice_of(a, worker, r);
    if (c == TF_AFFINITY_FIRST || c == TF_AFFINITY_NONE)
        return 0;
    uint64_t low = id < 0 ? 0 : (uint64_t)id & ((UINT64_C(1) << 62) - 1);
    return ((uint64_t)c << 62) | low;
}
