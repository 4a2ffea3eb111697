/* cmd_render.c: NOT IMPLEMENTED YET -- placeholder so the executable links while the command is
 * being written. */
#include "commands.h"
#include "log.h"

int cmd_render(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    tf_error("'render' is not implemented yet");
    return TF_EXIT_FAIL;
}
