/* log.h: the one place messages leave the program.  Errors are one line on stderr
 * ("terrafarm: what is wrong"); info and debug obey -q / -v.  Every message is written with a
 * single write(2) so lines from forked workers never interleave mid-line. */
#ifndef TF_LOG_H
#define TF_LOG_H

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

#endif
