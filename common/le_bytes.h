/* le_bytes.h: little-endian integers in byte buffers, the byte order of everything terrafarm
 * puts on the wire or on disk itself (frames and tuples, sealed records, chunk records, eroded
 * states and erosion checkpoints, the OpenCL cache's entries).  Byte by byte: any alignment,
 * any host order. */
#ifndef TF_LE_BYTES_H
#define TF_LE_BYTES_H

#include <stdint.h>

static inline void tf_le_put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static inline void tf_le_put64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static inline uint32_t tf_le_get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline uint64_t tf_le_get64(const uint8_t *p)
{
    return (uint64_t)tf_le_get32(p) | (uint64_t)tf_le_get32(p + 4) << 32;
}

#endif
