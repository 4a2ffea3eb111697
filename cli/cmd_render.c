/* cmd_render.c: `terrafarm render SCENE [options]`: parse the command line (docs/contract.md section 2)
 * into tf_render_opts and run the coordinator. */
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/commands.h"
#include "coordinator/render/coordinator.h"
#include "coordinator/render/render_option.h"
#include "log.h"

static const char usage[] =
    "usage: terrafarm render SCENE [options]\n"
    "\n"
    "Render SCENE to an OpenEXR file with forked local workers and any networked workers that\n"
    "join (terrafarm worker --connect HOST:PORT).  Finished rows are written in order and made\n"
    "durable, so an interrupted render continues with --resume.\n"
    "\n"
    "  -o, --output FILE.exr     output image (default out/<scene>.exr); a PNG preview goes beside it\n"
    "                            for an [animation] scene a pattern: its run of '#' becomes the\n"
    "                            frame number (default out/<scene>.####.exr)\n"
    "      --frames A-B[:STEP]   frames A to B (every STEP-th) of an [animation] scene (default:\n"
    "                            all of them); one farm renders them back to back\n"
    "      --frame N             frame N alone (the same bytes as inside a sequence)\n"
    "      --movie FILE.mp4|webm after the frames, assemble their PNG previews into a video at\n"
    "                            the scene's frame rate (needs ffmpeg)\n"
    "  -j, --workers N           local workers to fork (default: online CPUs); 0 = networked only\n"
    "      --wait-workers N      deal no task until N workers (forked ones included) have joined:\n"
    "                            a farm across N hosts starts when all are in (default 0: at once)\n"
    "      --tasks rows:K        scanline-block tasks of K rows\n"
    "      --tasks stamps:WxH    postage-stamp tasks of WxH pixels (default: stamps sized from the\n"
    "                            image and the worker count)\n"
    "      --watermark N         at most N tasks dealt beyond the write front (default: one band\n"
    "                            of tasks plus as many as hold 4 M pixels, but 3 to 16 a\n"
    "                            worker)\n"
    "      --affinity on|off     give each worker stamps in its own column range of the image\n"
    "                            first, then its neighbours', then the lowest left, so it re-uses\n"
    "                            what it evaluated there (default on; rows:K spans the width)\n"
    "      --size WxH            override the scene's image size\n"
    "      --pixel half|float    channel type of R, G, B, A (Z and samples stay float; default\n"
    "                            half). rows:K writes a scanline EXR, stamps:WxH a tiled one\n"
    "      --preview-interval MS rewrite the progress preview (FILE.png) at most this often\n"
    "                            while rendering (default 5000; it is also written at the end)\n"
    "      --verify-chunks       decode and scan forked workers' chunks too before accepting\n"
    "                            them (networked workers' always are, in a thread of their own)\n"
    "      --verify FRACTION     render that fraction of tasks (chosen from the scene hash) and\n"
    "                            every unchecked worker's results a second time on another\n"
    "                            worker and compare the bytes; a third render decides, the liar is\n"
    "                            excluded and its tasks dealt again (default 0: off)\n"
    "      --backend c|opencl|auto  backend of the local workers (default c; auto: OpenCL if\n"
    "                            a device works, else C with a warning)\n"
    "      --cl-device DEV       OpenCL device: P:D indices or a name substring\n"
    "                            (sets TERRAFARM_CL_DEVICE for the workers)\n"
    "      --listen HOST:PORT    accept networked workers there (default 127.0.0.1:7878, loopback)\n"
    "      --secret-file FILE    shared secret; required to listen on a non-loopback address\n"
    "      --resume              continue an interrupted render of the same scene into the same output\n"
    "      --overwrite           discard a partial render (or a foreign file) at the output\n"
    "      --stats FILE.json     write the run statistics\n"
    "      --terrain-cache SIZE  each local worker's budget for evaluated procedural terrain\n"
    "                            (e.g. 4M, 512M; default an eighth of memory, at most 512M)\n"
    "      --lease-timeout T     drop a worker silent this long and re-deal its task (default 15s;\n"
    "                            T is a number with ms, s, m or h; a bare number is milliseconds)\n"
    "      --http HOST:PORT|none the live dashboard and JSON API (default 127.0.0.1:7880; if that\n"
    "                            port is taken, a free one; the URL is logged)\n"
    "      --http-token-file F   the dashboard's token (else derived from --secret-file); a\n"
    "                            non-loopback --http needs one of the two\n"
    "      --on-done CMD         run /bin/sh -c CMD when the render ends, the outcome in\n"
    "                            TERRAFARM_STATUS, TERRAFARM_EXIT, TERRAFARM_OUTPUT, ... (README)\n"
    "  -q, --quiet               errors only\n"
    "  -v, --verbose             more detail (workers joining, re-dealt tasks)\n"
    "  -h, --help                this help\n";

/* An option render_option.c parses: 0, or -1 once its message is printed. */
static int set_value(tf_render_opts *o, const char *flag, const char *value)
{
    char err[512];
    if (tf_render_option_set(o, flag, value, err, sizeof err) == 0)
        return 0;
    tf_error("%s", err);
    return -1;
}

enum { O_TASKS = 256, O_WATERMARK, O_SIZE, O_BACKEND, O_LISTEN, O_SECRET, O_RESUME,
       O_OVERWRITE, O_STATS, O_LEASE, O_CL_DEVICE, O_FRAMES, O_FRAME, O_MOVIE, O_PIXEL,
       O_VERIFY_CHUNKS, O_VERIFY, O_PREVIEW_INTERVAL, O_HTTP, O_HTTP_TOKEN, O_ON_DONE,
       O_WAIT_WORKERS, O_TERRAIN_CACHE, O_AFFINITY };

static const struct option longopts[] = {
    {"output", required_argument, NULL, 'o'},
    {"workers", required_argument, NULL, 'j'},
    {"wait-workers", required_argument, NULL, O_WAIT_WORKERS},
    {"tasks", required_argument, NULL, O_TASKS},
    {"watermark", required_argument, NULL, O_WATERMARK},
    {"affinity", required_argument, NULL, O_AFFINITY},
    {"size", required_argument, NULL, O_SIZE},
    {"backend", required_argument, NULL, O_BACKEND},
    {"listen", required_argument, NULL, O_LISTEN},
    {"secret-file", required_argument, NULL, O_SECRET},
    {"resume", no_argument, NULL, O_RESUME},
    {"overwrite", no_argument, NULL, O_OVERWRITE},
    {"stats", required_argument, NULL, O_STATS},
    {"lease-timeout", required_argument, NULL, O_LEASE},
    {"terrain-cache", required_argument, NULL, O_TERRAIN_CACHE},
    {"cl-device", required_argument, NULL, O_CL_DEVICE},
    {"frames", required_argument, NULL, O_FRAMES},
    {"frame", required_argument, NULL, O_FRAME},
    {"movie", required_argument, NULL, O_MOVIE},
    {"pixel", required_argument, NULL, O_PIXEL},
    {"verify-chunks", no_argument, NULL, O_VERIFY_CHUNKS},
    {"verify", required_argument, NULL, O_VERIFY},
    {"preview-interval", required_argument, NULL, O_PREVIEW_INTERVAL},
    {"http", required_argument, NULL, O_HTTP},
    {"http-token-file", required_argument, NULL, O_HTTP_TOKEN},
    {"on-done", required_argument, NULL, O_ON_DONE},
    {"quiet", no_argument, NULL, 'q'},
    {"verbose", no_argument, NULL, 'v'},
    {"help", no_argument, NULL, 'h'},
    {NULL, 0, NULL, 0},
};

/* An option that names a path or a switch: taken as it is. */
static void set_plain(tf_render_opts *o, int c, const char *arg)
{
    switch (c) {
    case 'o': o->output = arg; break;
    case O_LISTEN: o->listen = arg; break;
    case O_SECRET: o->secret_file = arg; break;
    case O_RESUME: o->resume = 1; break;
    case O_OVERWRITE: o->overwrite = 1; break;
    case O_STATS: o->stats_path = arg; break;
    case O_HTTP: o->http = arg; break;
    case O_HTTP_TOKEN: o->http_token_file = arg; break;
    case O_ON_DONE: o->on_done = arg; break;
    case O_CL_DEVICE: setenv("TERRAFARM_CL_DEVICE", arg, 1); break;
    case O_MOVIE: o->movie = arg; break;
    case O_VERIFY_CHUNKS: o->verify_chunks = 1; break;
    case 'q': o->quiet = 1; break;
    case 'v': o->verbose = 1; break;
    }
}

/* One option (longopts[longindex] for a long one) into o: 0, or -1 once refused. */
static int render_option(tf_render_opts *o, int c, int longindex, const char *arg)
{
    char flag[40];
    switch (c) {
    case 'j':
        return set_value(o, "--workers", arg);
    case O_WAIT_WORKERS: case O_TASKS: case O_WATERMARK: case O_AFFINITY: case O_SIZE:
    case O_BACKEND: case O_FRAMES: case O_FRAME: case O_PIXEL: case O_VERIFY:
    case O_PREVIEW_INTERVAL: case O_LEASE:
        snprintf(flag, sizeof flag, "--%s", longopts[longindex].name);
        return set_value(o, flag, arg);
    case O_TERRAIN_CACHE:
        return tf_parse_byte_size("--terrain-cache", arg, &o->terrain_cache) ? -1 : 0;
    default:
        set_plain(o, c, arg);
        return 0;
    }
}

/* The command line into o: -1 to render, or the exit status (--help, or a refusal). */
static int parse_render_args(tf_render_opts *o, int argc, char **argv)
{
    int c, longindex = 0;
    optind = 1;
    opterr = 0;
    while ((c = getopt_long(argc, argv, ":o:j:qvh", longopts, &longindex)) != -1) {
        if (c == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        }
        if (c == ':' || c == '?') {
            tf_error(c == ':' ? "render: option '%s' needs a value (see terrafarm render --help)"
                              : "render: unknown option '%s' (see terrafarm render --help)",
                     argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
        if (render_option(o, c, longindex, optarg))
            return TF_EXIT_USAGE;
    }
    if (optind != argc - 1) {
        tf_error(optind >= argc ? "render: missing SCENE (see terrafarm render --help)"
                                : "render: expected one SCENE, got extra arguments (see "
                                  "terrafarm render --help)");
        return TF_EXIT_USAGE;
    }
    if (o->resume && o->overwrite) {
        tf_error("render: --resume and --overwrite contradict each other");
        return TF_EXIT_USAGE;
    }
    o->scene_path = argv[optind];
    return -1;
}

int cmd_render(int argc, char **argv)
{
    tf_render_opts o;
    tf_render_opts_init(&o);
    int status = parse_render_args(&o, argc, argv);
    if (status >= 0)
        return status;
    if (o.quiet)
        tf_log_set_level(TF_LOG_WARN);
    if (o.verbose)
        tf_log_set_level(TF_LOG_DEBUG);
    return tf_coordinator_run(&o);
}
