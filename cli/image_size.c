/* image_size.c: the `--size WxH` argument of paint (commands.h); the rule itself is
 * coordinator/render/render_option.c's, which render and the farm's jobs use. */
#include "cli/commands.h"

#include "coordinator/render/render_option.h"
#include "log.h"

int tf_parse_image_size(const char *flag, const char *text, int *w, int *h)
{
    char err[256];
    if (tf_image_size_parse(flag, text, w, h, err, sizeof err) == 0)
        return 0;
    tf_error("%s", err);
    return -1;
}
