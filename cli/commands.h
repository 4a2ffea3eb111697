/* commands.h: the subcommands of bin/terrafarm.  Each takes the arguments after its name
 * (argv[0] is the command name) and returns the process exit status. */
#ifndef TF_COMMANDS_H
#define TF_COMMANDS_H

int cmd_render(int argc, char **argv);      /* cmd_render.c: the coordinator */
int cmd_worker(int argc, char **argv);      /* cmd_worker.c: a networked worker */
int cmd_heightfield(int argc, char **argv); /* cmd_heightfield.c: export the terrain */
int cmd_bench(int argc, char **argv);       /* cmd_bench.c: speedup against worker count */
int cmd_status(int argc, char **argv);      /* cmd_status.c: a running render's dashboard */
int cmd_farm(int argc, char **argv);        /* cmd_farm.c: a standing farm */
int cmd_jobs(int argc, char **argv);        /* cmd_jobs.c: submit, jobs, job, cancel, ... */
int cmd_paint(int argc, char **argv);       /* cmd_paint.c: Raypaint, the interactive view */

/* Exit statuses shared by all commands. */
/* `--terrain-cache SIZE` and the like: a byte count with an optional K, M, G or T (powers of
 * 1024) and an optional B or iB.  0, or -1 after one line naming flag and text. */
#include <stddef.h>
int tf_parse_byte_size(const char *flag, const char *text, size_t *bytes);
/* `--size WxH` of paint: sides 1 to 65536.  0, or -1 after one line naming flag and text. */
int tf_parse_image_size(const char *flag, const char *text, int *w, int *h);

enum { TF_EXIT_OK = 0, TF_EXIT_FAIL = 1, TF_EXIT_USAGE = 2 };

#endif
