/* image_size.c: the `--size WxH` argument of render and paint (commands.h). */
#include "cli/commands.h"

#include <stdlib.h>

#include "log.h"

int tf_parse_image_size(const char *flag, const char *text, int *w, int *h)
{
    char *end;
    long a = strtol(text, &end, 10);
    if (end == text || (*end != 'x' && *end != 'X'))
        goto bad;
    const char *p = end + 1;
    long b = strtol(p, &end, 10);
    if (end == p || *end || a < 1 || b < 1 || a > 65536 || b > 65536)
        goto bad;
    *w = (int)a;
    *h = (int)b;
    return 0;
bad:
    tf_error("%s '%s': expected WxH with sides from 1 to 65536", flag, text);
    return -1;
}
