/* render_option.h: the values of `terrafarm render`'s options, parsed in one place.  The
 * command line (cli/cmd_render.c) sets them through here, and so does the standing farm when a
 * job is submitted (coordinator/farm/farm_jobs.c): a job whose option would stop its render is
 * refused at the door with the render's own one-line message, not accepted and failed later. */
#ifndef TF_RENDER_OPTION_H
#define TF_RENDER_OPTION_H

#include <stddef.h>

#include "coordinator/render/coordinator.h"

/* Set option `flag` (its long name: "--size", "--lease-timeout", ...) to `value` in o.
 * 0: set; -1: the value is not one the option takes, a one-line message naming the flag and
 * what it expects in err; 1: flag is not an option parsed here (err untouched).  The options
 * that take a file or an address (--output, --listen, --stats, ...) and the flags without a
 * value are not parsed here. */
int tf_render_option_set(tf_render_opts *o, const char *flag, const char *value, char *err,
                         size_t errlen);

/* "WxH" with sides 1..65536 (--size of render and paint): 0, or -1 with a message naming flag. */
int tf_image_size_parse(const char *flag, const char *text, int *w, int *h, char *err,
                        size_t errlen);

#endif
