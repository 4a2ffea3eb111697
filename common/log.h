/* log.h: the one place messages leave the program.  Errors are one line on stderr
 * ("terrafarm: what is wrong"); info and debug obey -q / -v.  Every message is written with a
 * single write(2) so lines from forked workers never interleave mid-line. */
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

/* The one error formatter.  Functions that can fail take (char *err, size_t errlen) and put one
 * line there saying what is wrong, naming the file, line or peer; the caller decides whether it
 * becomes a log line or an exit.  Writes nothing if err is NULL or errlen is 0; returns -1 so
 * that `return tf_seterr(err, errlen, "...")` reads as it does. */
int tf_seterr(char *err, size_t errlen, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
int tf_vseterr(char *err, size_t errlen, const char *fmt, va_list ap);

#endif
