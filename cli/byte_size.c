/* byte_size.c: the `--terrain-cache SIZE` argument of render and worker (commands.h). */
#include "cli/commands.h"

#include <ctype.h>
#include <stdint.h>
#include <stdlib.h>

#include "log.h"

int tf_parse_byte_size(const char *flag, const char *text, size_t *bytes)
{
    char *end;
    double v = strtod(text, &end);
    double unit = 1;
    switch (toupper((unsigned char)*end)) {
    case 'K': unit = 1024.0; end++; break;
    case 'M': unit = 1024.0 * 1024; end++; break;
    case 'G': unit = 1024.0 * 1024 * 1024; end++; break;
    case 'T': unit = 1024.0 * 1024 * 1024 * 1024; end++; break;
    default: break;
    }
    if (toupper((unsigned char)*end) == 'B' || (*end == 'i' && end[1] == 'B'))
        end += *end == 'i' ? 2 : 1;
    if (end == text || *end || !(v >= 0) || !(v * unit <= (double)(SIZE_MAX / 2))) {
        tf_error("%s '%s': expected a size in bytes such as 4M, 512M or 2G (K, M, G, T: "
                 "powers of 1024)", flag, text);
        return -1;
    }
    *bytes = (size_t)(v * unit);
    return 0;
}
