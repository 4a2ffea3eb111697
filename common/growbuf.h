/* growbuf.h: grow a byte buffer to hold at least `need` bytes, doubling from 4 KB, for the
 * encoders that append a task's chunks into one payload (image/exrencode.c and the simulated
 * workers' recorded payloads, worker/payloads.c).  0, or -1 out of memory (the buffer is
 * unchanged). */
#ifndef TF_GROWBUF_H
#define TF_GROWBUF_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

static inline int tf_growbuf(uint8_t **buf, size_t *cap, size_t need)
{
    if (need <= *cap)
        return 0;
    size_t n = *cap ? *cap : 4096;
    while (n < need)
        n *= 2;
    uint8_t *p = realloc(*buf, n);
    if (!p)
        return -1;
    *buf = p;
    *cap = n;
    return 0;
}

#endif
