/* clock.h: the program's one clock.  Durations and deadlines are measured on CLOCK_MONOTONIC
 * (immune to the wall clock being set); tf_realtime_in() turns a relative wait into the
 * CLOCK_REALTIME deadline that pthread_cond_timedwait wants. */
#ifndef TF_CLOCK_H
#define TF_CLOCK_H

#include <stdint.h>
#include <time.h>

/* Nanoseconds on `id` (CLOCK_MONOTONIC, CLOCK_PROCESS_CPUTIME_ID, CLOCK_THREAD_CPUTIME_ID...). */
int64_t tf_clock_ns(clockid_t id);

/* Monotonic time since an arbitrary origin, in the unit the caller counts in. */
static inline int64_t tf_now_ns(void) { return tf_clock_ns(CLOCK_MONOTONIC); }
static inline int64_t tf_now_ms(void) { return tf_now_ns() / 1000000; }
static inline double tf_now_msf(void) { return (double)tf_now_ns() * 1e-6; }
static inline double tf_now_s(void) { return (double)tf_now_ns() * 1e-9; }

/* A duration as written on the command line: a number and an optional unit, "ms", "s", "m"
 * (minutes) or "h", e.g. "500ms", "15s", "1.5s", "2m"; a bare number is milliseconds (so
 * "15000" is still 15 s).  No sign, no blanks.  Rounded to whole milliseconds.  Returns 0 and
 * *ms, or -1 if text is not such a duration or exceeds 30 days. */
int tf_parse_duration_ms(const char *text, int64_t *ms);

/* The CLOCK_REALTIME instant `ms` milliseconds from now (ms may be fractional). */
struct timespec tf_realtime_in(double ms);

#endif
