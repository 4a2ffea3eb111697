/* clock.c: see clock.h. */
#include "clock.h"

#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DURATION_MAX_MS (30.0 * 24 * 3600 * 1000)

int tf_parse_duration_ms(const char *text, int64_t *ms)
{
    static const struct { const char *name; double ms; } units[] = {
        {"", 1}, {"ms", 1}, {"s", 1000}, {"m", 60000}, {"h", 3600000}};
    if (!text || !isdigit((unsigned char)text[0]))
        return -1; /* no sign, no blank, no "inf"/"nan", no leading '.' */
    const char *p = text;
    while (isdigit((unsigned char)*p))
        p++;
    if (*p == '.') {
        p++;
        if (!isdigit((unsigned char)*p))
            return -1;
        while (isdigit((unsigned char)*p))
            p++;
    }
    char *end;
    double v = strtod(text, &end);
    if (end != p) /* strtod would have read an exponent or hex: not our syntax */
        return -1;
    for (size_t i = 0; i < sizeof units / sizeof units[0]; i++)
        if (strcmp(p, units[i].name) == 0) {
            double total = v * units[i].ms;
            if (!(total <= DURATION_MAX_MS))
                return -1;
            *ms = (int64_t)llround(total);
            return 0;
        }
    return -1;
}

int64_t tf_clock_ns(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

struct timespec tf_realtime_in(double ms)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    int64_t ns = ts.tv_nsec + (int64_t)(ms * 1e6);
    ts.tv_sec += ns / 1000000000;
    ts.tv_nsec = ns % 1000000000;
    return ts;
}
