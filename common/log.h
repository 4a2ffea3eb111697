/* log.h: the one place messages leave the program.  Errors are one line on stderr
 * ("terrafarm: what is wrong"); info and debug obey -q / -v.  Every message is written with a
 * single write(2) so lines from forked workers never interleave mid-line, and is one line
 * whatever it quotes: control bytes (a peer's newline or escape sequence) are written as '?'. */
#ifndef TF_LOG_H
#define TF_LOG_H

#include <stdarg.h>
#include <stddef.h>

enum tf_log_level { TF_LOG_ERROR = 0, TF_LOG_WARN = 1, TF_LOG_INFO = 2, TF_LOG_DEBUG = 3 };

void tf_log_set_level(int level);
int  tf_log_get_level(void);
/* Prefix placed after "terrafarm" in every line, e.g. "worker 3" -> "terrafarm[worker 3]: ". */
void tf_log_set_tag(const char *tag);

void tf_error(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void tf_warn(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void tf_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void tf_debug(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* tf_error, then exit(status). */
void tf_die(int status, const char *fmt, ...) __attribute__((format(printf, 2, 3), noreturn));

/* Each control byte of s[0..len) (a newline, an escape sequence) overwritten with '?': what
 * every message and every string shown from a peer goes through. */
void tf_one_line(char *s, size_t len);

/* s shown safely in a message or a table: at most n - 1 bytes of it in buf, control bytes as
 * '?', "..." where it was cut; "-" for NULL.  Returns buf. */
const char *tf_printable(const char *s, char *buf, size_t n);

/* The one error formatter.  Functions that can fail take (char *err, size_t errlen) and put one
 * line there saying what is wrong, naming the file, line or peer; the caller decides whether it
 * becomes a log line or an exit.  Writes nothing if err is NULL or errlen is 0; returns -1 so
 * that `return tf_seterr(err, errlen, "...")` reads as it does. */
int tf_seterr(char *err, size_t errlen, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
int tf_vseterr(char *err, size_t errlen, const char *fmt, va_list ap);

/* A rate limiter for a repeated message (one static instance per message site): at most
 * TF_RATELIMIT_BURST lines per TF_RATELIMIT_WINDOW_MS; the first line after a window in which
 * some were held back says how many.  A peer that provokes a warning a hundred thousand times
 * costs a few lines a second, not a flooded log.  Not thread-safe (one thread per site). */
#define TF_RATELIMIT_BURST 20
#define TF_RATELIMIT_WINDOW_MS 5000
typedef struct tf_ratelimit {
    int burst;            /* lines per window; 0: TF_RATELIMIT_BURST */
    long long window_start_ms;
    int in_window;        /* lines emitted in this window */
    long long suppressed; /* lines held back since the last one emitted */
} tf_ratelimit;
void tf_warn_limited(tf_ratelimit *rl, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* 1 when a line may be written now (and counts it), 0 when it is held back; *held (may be
 * NULL) receives the number held back before this one (reset once reported). */
int tf_ratelimit_take(tf_ratelimit *rl, long long now_ms, long long *held);

#endif
