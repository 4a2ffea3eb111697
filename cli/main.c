/* main.c: bin/terrafarm, one executable with subcommands (docs/contract.md section 2).  This file only
 * dispatches; each subcommand lives in its own cmd_*.c. */
#include <stdio.h>
#include <string.h>

#include "cli/commands.h"
#include "log.h"

static const char usage[] =
    "usage: terrafarm COMMAND [options]\n"
    "\n"
    "A parallel, distributed render farm for procedural fractal terrain.\n"
    "\n"
    "commands:\n"
    "  render SCENE [options]          render SCENE to OpenEXR with forked and networked workers\n"
    "  worker --connect HOST:PORT      join a render as a networked worker\n"
    "  heightfield SCENE -o FILE       export the terrain as 16-bit PNG or float EXR\n"
    "  bench SCENE --workers 1,2,4     measure speedup against worker count\n"
    "  status HOST:PORT [--json]       a running render's progress, from its dashboard\n"
    "  farm --listen HOST:PORT --state DIR   a standing farm: a durable queue of jobs\n"
    "  submit SCENE [options]          queue a job on a standing farm (prints its id)\n"
    "  jobs | job ID                   the farm's jobs, one job (and its output)\n"
    "  cancel|pause|resume ID, priority ID N   steer a job\n"
    "  paint SCENE [options]           paint SCENE progressively in the browser (Raypaint)\n"
    "\n"
    "  terrafarm COMMAND --help        options of one command\n"
    "  terrafarm --version             print the version\n";

int main(int argc, char **argv)
{
    if (argc < 2) {
        fputs(usage, stderr);
        return TF_EXIT_USAGE;
    }
    const char *cmd = argv[1];
    if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
        fputs(usage, stdout);
        return TF_EXIT_OK;
    }
    if (!strcmp(cmd, "--version") || !strcmp(cmd, "-V")) {
        printf("terrafarm %s\n", TF_VERSION);
        return TF_EXIT_OK;
    }
    static const struct {
        const char *name;
        int (*fn)(int, char **);
    } commands[] = {
        {"render", cmd_render},
        {"worker", cmd_worker},
        {"heightfield", cmd_heightfield},
        {"bench", cmd_bench},
        {"status", cmd_status},
        {"farm", cmd_farm},
        {"submit", cmd_jobs},
        {"jobs", cmd_jobs},
        {"job", cmd_jobs},
        {"cancel", cmd_jobs},
        {"pause", cmd_jobs},
        {"resume", cmd_jobs},
        {"priority", cmd_jobs},
        {"paint", cmd_paint},
    };
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(cmd, commands[i].name))
            return commands[i].fn(argc - 1, argv + 1);
    tf_error("unknown command '%s' (try 'terrafarm --help')", cmd);
    return TF_EXIT_USAGE;
}
