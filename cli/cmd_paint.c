/* cmd_paint.c: `terrafarm paint SCENE`: Raypaint, the scene coming into focus in the browser on
 * forked and networked workers (coordinator/paint/paint.h; docs/paint.md). */
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/commands.h"
#include "coordinator/paint/paint.h"
#include "image/exrlayout.h"
#include "log.h"

static const char usage[] =
    "usage: terrafarm paint SCENE [options]\n"
    "\n"
    "Paint SCENE progressively in the browser: a coarse picture at once, sharpening where the\n"
    "contrast is and first where you click, until every pixel is the one terrafarm render makes.\n"
    "The page edits the camera, the sun and the mist (painting starts again), saves the\n"
    "edited scene and submits it to a standing farm.\n"
    "\n"
    "  -j, --workers N           forked workers (default: one a core; 0 with --listen)\n"
    "      --listen HOST:PORT    networked workers join here (terrafarm worker --connect)\n"
    "      --secret-file FILE    the farm secret (needed to listen beyond loopback)\n"
    "      --http HOST:PORT      the page (default 127.0.0.1 on a free port, printed)\n"
    "      --http-token-file F   the page's token (default: derived from --secret-file)\n"
    "      --size WxH            override the scene's image size\n"
    "      --pixel half|float    as terrafarm render (default half)\n"
    "  -o, --output FILE         write the painted image (OpenEXR) once every pixel is exact\n"
    "      --save FILE           where the page's Save writes the edited scene\n"
    "      --farm HOST:PORT      the standing farm the page's Submit sends the view to\n"
    "      --farm-token-file F   the token Submit gives the farm (default $TERRAFARM_TOKEN_FILE)\n"
    "      --until-painted       leave once the view is painted (and written, with -o)\n"
    "      --paused              start paused (the page's Resume starts the dealing)\n"
    "      --wait-workers N      deal nothing until N workers (forked ones included) have joined\n"
    "      --root N              side of the quad-tree's roots (default 64)\n"
    "      --levels N            quad-tree levels a task descends (default 2)\n"
    "      --leaf N              cells of this side are rendered exactly (default 16)\n"
    "      --fine N              ... after their lattice at this stride (default 2)\n"
    "      --task-rays N         rays per task, about (default 16384)\n"
    "  -q, --quiet / -v, --verbose\n"
    "  -h, --help\n";

static int parse_int(const char *flag, const char *text, int lo, int hi, int *out)
{
    char *end;
    long v = strtol(text, &end, 10);
    if (end == text || *end || v < lo || v > hi) {
        tf_error("%s '%s': expected a whole number from %d to %d", flag, text, lo, hi);
        return -1;
    }
    *out = (int)v;
    return 0;
}

enum { O_LISTEN = 256, O_SECRET, O_HTTP, O_HTTP_TOKEN, O_SIZE, O_PIXEL, O_SAVE, O_FARM,
       O_UNTIL, O_PAUSED, O_ROOT, O_LEVELS, O_LEAF, O_RAYS, O_FINE, O_FARM_TOKEN,
       O_WAIT_WORKERS };

static const struct option longopts[] = {
    {"workers", required_argument, NULL, 'j'}, {"listen", required_argument, NULL, O_LISTEN},
    {"secret-file", required_argument, NULL, O_SECRET}, {"http", required_argument, NULL, O_HTTP},
    {"http-token-file", required_argument, NULL, O_HTTP_TOKEN},
    {"size", required_argument, NULL, O_SIZE}, {"pixel", required_argument, NULL, O_PIXEL},
    {"output", required_argument, NULL, 'o'}, {"save", required_argument, NULL, O_SAVE},
    {"farm", required_argument, NULL, O_FARM},
    {"farm-token-file", required_argument, NULL, O_FARM_TOKEN},
    {"until-painted", no_argument, NULL, O_UNTIL},
    {"paused", no_argument, NULL, O_PAUSED},
    {"wait-workers", required_argument, NULL, O_WAIT_WORKERS},
    {"root", required_argument, NULL, O_ROOT},
    {"levels", required_argument, NULL, O_LEVELS}, {"leaf", required_argument, NULL, O_LEAF},
    {"task-rays", required_argument, NULL, O_RAYS}, {"fine", required_argument, NULL, O_FINE}, {"quiet", no_argument, NULL, 'q'},
    {"verbose", no_argument, NULL, 'v'}, {"help", no_argument, NULL, 'h'},
    {NULL, 0, NULL, 0},
};

/* One option into o: 0, 1 (help printed), or -1 (a usage error, said). */
static int take_option(int ch, tf_paint_opts *o, char **argv)
{
    tf_paint_params *p = &o->params;
    switch (ch) {
    case 'j': return parse_int("--workers", optarg, 0, 1024, &o->workers);
    case O_LISTEN: o->listen = optarg; return 0;
    case O_SECRET: o->secret_file = optarg; return 0;
    case O_HTTP: o->http = optarg; return 0;
    case O_HTTP_TOKEN: o->http_token_file = optarg; return 0;
    case O_SIZE: return tf_parse_image_size("--size", optarg, &o->width, &o->height);
    case O_PIXEL:
        if (!tf_pixel_type_parse(optarg, &o->pixel))
            return 0;
        tf_error("--pixel '%s': expected half or float", optarg);
        return -1;
    case 'o': o->output = optarg; return 0;
    case O_SAVE: o->save = optarg; return 0;
    case O_FARM: o->farm = optarg; return 0;
    case O_FARM_TOKEN: o->farm_token_file = optarg; return 0;
    case O_UNTIL: o->until_painted = 1; return 0;
    case O_PAUSED: o->paused = 1; return 0;
    case O_WAIT_WORKERS: return parse_int("--wait-workers", optarg, 0, 1 << 20, &o->wait_workers);
    case O_ROOT: return parse_int("--root", optarg, 1, 1024, &p->root);
    case O_LEVELS: return parse_int("--levels", optarg, 1, 10, &p->levels);
    case O_LEAF: return parse_int("--leaf", optarg, 1, 1024, &p->leaf);
    case O_RAYS: return parse_int("--task-rays", optarg, 1, 1 << 24, &p->task_rays);
    case O_FINE: return parse_int("--fine", optarg, 1, 1024, &p->fine);
    case 'q': tf_log_set_level(TF_LOG_ERROR); return 0;
    case 'v': tf_log_set_level(TF_LOG_DEBUG); return 0;
    case 'h': fputs(usage, stdout); return 1;
    case ':': tf_error("%s needs a value", argv[optind - 1]); return -1;
    default: tf_error("unknown option '%s' (see terrafarm paint --help)", argv[optind - 1]);
        return -1;
    }
}

int cmd_paint(int argc, char **argv)
{
    tf_paint_opts o;
    tf_paint_opts_init(&o);
    int ch;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":j:o:qvh", longopts, NULL)) != -1) {
        int rc = take_option(ch, &o, argv);
        if (rc)
            return rc > 0 ? TF_EXIT_OK : TF_EXIT_USAGE;
    }
    if (optind + 1 != argc) {
        fputs(usage, stderr);
        return TF_EXIT_USAGE;
    }
    o.scene_path = argv[optind];
    return tf_paint_run(&o);
}
