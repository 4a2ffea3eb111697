/* verify.h: spot checks that use the determinism invariant (--verify FRACTION).  A pixel
 * depends only on the scene and its coordinates, and a task's encoded chunks only on its
 * pixels, so any task rendered twice by honest workers gives the same bytes.  The supervisor
 * re-renders a random fraction of tasks (its seed never leaves the coordinator) and every
 * result of a worker that has not yet passed a check, on a different worker, and compares the
 * results' digests; on a mismatch a third worker decides, the one that disagrees is excluded
 * and every task it rendered is dealt again, those already written too, through a rewind of
 * the output (supervisor_verify.c, "spot checks").  This file holds the two pure parts: which tasks
 * are checked, and the digest of a result. */
#ifndef TF_VERIFY_H
#define TF_VERIFY_H

#include <stdint.h>

#include "farmproto.h"

#define TF_DIGEST_BYTES 32

/* The seed of a render's choice: random, and never sent anywhere.  A seed a worker could know
 * (the scene hash was one) would let a liar lie only on the tasks that will not be checked. */
uint64_t tf_verify_seed(void);
/* 1 if task id is among the fraction checked under seed (fraction <= 0: never, >= 1: always). */
int tf_verify_selected(uint64_t seed, double fraction, int64_t id);
/* BLAKE2b-256 of what a result says about its pixels: index, chunks and preview share. */
void tf_result_digest(const tf_result_msg *m, uint8_t out[TF_DIGEST_BYTES]);

#endif
