/* log.c: see log.h. */
#include "log.h"
#include "clock.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int log_level = TF_LOG_INFO;
static char log_tag[64];

void tf_log_set_level(int level) { log_level = level; }
int tf_log_get_level(void) { return log_level; }

void tf_log_set_tag(const char *tag)
{
    snprintf(log_tag, sizeof log_tag, "%s", tag ? tag : "");
}

/* A message is one line, whatever it quotes: a peer's string (a worker's failure, a host name,
 * a service's answer) with a newline could forge a line of its own, and one with an escape
 * sequence could drive the terminal.  Every control byte becomes '?'. */
void tf_one_line(char *s, size_t len)
{
    for (size_t i = 0; i < len; i++)
        if ((unsigned char)s[i] < 0x20 || s[i] == 0x7f)
            s[i] = '?';
}

static void emit(int level, const char *kind, const char *fmt, va_list ap)
{
    if (level > log_level)
        return;
    char line[2048];
    int n = snprintf(line, sizeof line, "terrafarm%s%s%s: %s", log_tag[0] ? "[" : "", log_tag,
                     log_tag[0] ? "]" : "", kind);
    if (n < 0 || n >= (int)sizeof line)
        n = 0;
    int m = vsnprintf(line + n, sizeof line - (size_t)n - 1, fmt, ap);
    if (m < 0)
        m = 0;
    size_t len = strlen(line);
    while (len > 0 && line[len - 1] == '\n')
        len--;
    tf_one_line(line, len);
    line[len++] = '\n';
    ssize_t w = write(STDERR_FILENO, line, len);
    (void)w;
}

#define DEFINE_LOG(name, level, kind)                                                          \
    void name(const char *fmt, ...)                                                            \
    {                                                                                          \
        va_list ap;                                                                            \
        va_start(ap, fmt);                                                                     \
        emit(level, kind, fmt, ap);                                                            \
        va_end(ap);                                                                            \
    }

DEFINE_LOG(tf_error, TF_LOG_ERROR, "")
DEFINE_LOG(tf_warn, TF_LOG_WARN, "warning: ")
DEFINE_LOG(tf_info, TF_LOG_INFO, "")
DEFINE_LOG(tf_debug, TF_LOG_DEBUG, "debug: ")

void tf_die(int status, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit(TF_LOG_ERROR, "", fmt, ap);
    va_end(ap);
    exit(status);
}

const char *tf_printable(const char *s, char *buf, size_t n)
{
    if (!n)
        return buf;
    if (!s)
        s = "-";
    const size_t len = strlen(s);
    size_t k = len < n ? len : (n > 4 ? n - 4 : n - 1); /* room for "..." where cut */
    memcpy(buf, s, k);
    tf_one_line(buf, k);
    if (k < len && n > 4)
        memcpy(buf + k, "...", 3), k += 3;
    buf[k] = '\0';
    return buf;
}

int tf_vseterr(char *err, size_t errlen, const char *fmt, va_list ap)
{
    if (err && errlen > 0)
        vsnprintf(err, errlen, fmt, ap);
    return -1;
}

int tf_seterr(char *err, size_t errlen, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    tf_vseterr(err, errlen, fmt, ap);
    va_end(ap);
    return -1;
}

int tf_ratelimit_take(tf_ratelimit *rl, long long now_ms, long long *held)
{
    if (rl->window_start_ms == 0 || now_ms - rl->window_start_ms >= TF_RATELIMIT_WINDOW_MS) {
        rl->window_start_ms = now_ms ? now_ms : 1;
        rl->in_window = 0;
    }
    if (rl->in_window >= (rl->burst > 0 ? rl->burst : TF_RATELIMIT_BURST)) {
        rl->suppressed++;
        return 0;
    }
    rl->in_window++;
    if (held)
        *held = rl->suppressed;
    rl->suppressed = 0;
    return 1;
}

void tf_warn_limited(tf_ratelimit *rl, const char *fmt, ...)
{
    long long held = 0;
    if (!tf_ratelimit_take(rl, (long long)tf_now_ms(), &held))
        return;
    char line[1800];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    if (held > 0)
        tf_warn("%s (%lld similar messages suppressed)", line, held);
    else
        tf_warn("%s", line);
}
