/* erosion_film.c: an erosion film (Musgrave 2.4.4; erosion_film.h): frame k is a still of the
 * terrain after k * erosion_steps steps, rendered by the farm while a forked eroder works
 * ahead on the next frames' terrain.
 *
 * Steps: 1. the frames and their outputs; 2. the eroder: one child process that erodes frame
 * 1, 2, ... in order, each continuing from the previous frame's checkpoint (exact:
 * erosion_checkpoint.h) and leaving its terrain in the erosion cache beside the output; 3. for
 * each frame, wait until its terrain is in the cache (or the eroder has failed), then render
 * it as a still of its own scene (the camera and sun of that frame, fluvial_steps = k * n),
 * which reads the terrain from the cache. */
#include "coordinator/erosion/erosion_film.h"

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "coordinator/render/frames.h"
#include "terrain/eroded.h"
#include "terrain/erosion_checkpoint.h"
#include "terrain/terrain_build.h"
#include "log.h"

typedef struct film {
    const tf_render_opts *o;
    tf_scene *s;
    char *pattern;
    int first, last, step;
    pid_t eroder;
    int eroder_status; /* -1 running, else its exit status */
} film;

/* Frame k's own scene: the film's camera and sun at k, a still, fluvial_steps = k * n; its
 * text is the canonical form, so it reads back the same.  NULL on failure (err set). */
static tf_scene *frame_scene(const film *f, int k, char *err, size_t errlen)
{
    tf_scene *c = malloc(sizeof *c);
    if (!c) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    memcpy(c, f->s, sizeof *c); /* a shallow copy: only read, never freed as a scene */
    tf_scene_apply_frame(c, k);
    c->terrain.erosion.fluvial_steps = k * f->s->animation.erosion_steps;
    memset(&c->animation, 0, sizeof c->animation);
    char *text = tf_scene_canonical(c);
    free(c);
    char name[300];
    snprintf(name, sizeof name, "%s (frame %d)", f->s->path, k);
    tf_scene *fs = text ? tf_scene_parse_text(name, text, strlen(text), err, errlen) : NULL;
    free(text);
    if (fs && f->s->heightmap) {
        uint8_t *copy = malloc(f->s->heightmap_len);
        if (copy)
            memcpy(copy, f->s->heightmap, f->s->heightmap_len);
        if (!copy || tf_scene_attach_heightmap(fs, copy, f->s->heightmap_len,
                                               f->s->heightmap_name, err, errlen) != 0) {
            tf_scene_free(fs);
            return NULL;
        }
    }
    return fs;
}

/* 2. The child: every frame's terrain in order, into the cache. */
static void eroder(const film *f)
{
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    signal(SIGINT, SIG_IGN);
    tf_log_set_tag("eroder");
    char err[1024];
    for (int k = 1; k <= f->last; k++) {
        tf_scene *fs = frame_scene(f, k, err, sizeof err);
        uint8_t *b = NULL;
        size_t len;
        if (!fs || tf_terrain_eroded_bytes(&fs->terrain, 0, &b, &len, NULL, err, sizeof err)) {
            tf_error("frame %d: %s", k, err);
            _exit(1);
        }
        free(b);
        tf_scene_free(fs);
    }
    _exit(0);
}

static int start_eroder(film *f)
{
    f->eroder_status = 0;
    if (f->last < 1)
        return 0; /* frame 0 only: nothing to erode */
    fflush(NULL);
    f->eroder = fork();
    if (f->eroder < 0) {
        tf_error("fork: cannot start the eroder");
        return -1;
    }
    if (f->eroder == 0)
        eroder(f);
    f->eroder_status = -1;
    return 0;
}

/* 3. Frame k's terrain is in the cache, or the eroder has ended without it: 0 or -1. */
static int wait_for_terrain(film *f, const tf_scene *fs, int k)
{
    if (fs->terrain.erosion.fluvial_steps <= 0)
        return 0;
    char path[600];
    tf_eroded_cache_path(&fs->terrain, path, sizeof path);
    struct stat st;
    const struct timespec tick = {0, 50 * 1000 * 1000};
    while (stat(path, &st) != 0) {
        int status;
        if (f->eroder_status < 0 && waitpid(f->eroder, &status, WNOHANG) == f->eroder)
            f->eroder_status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        if (f->eroder_status >= 0 && stat(path, &st) != 0) {
            tf_error("frame %d: the eroder ended (status %d) without its terrain", k,
                     f->eroder_status);
            return -1;
        }
        nanosleep(&tick, NULL);
    }
    return 0;
}

static void stop_eroder(film *f)
{
    if (f->eroder_status < 0) {
        kill(f->eroder, SIGKILL);
        waitpid(f->eroder, NULL, 0);
        f->eroder_status = 137;
    }
}

/* 1. The frames asked for, and where they go. */
static int plan_frames(film *f)
{
    const tf_render_opts *o = f->o;
    f->first = 0;
    f->last = f->s->animation.frames - 1;
    f->step = 1;
    if (o->frames_given) {
        if (o->frame_last >= f->s->animation.frames) {
            tf_error("--frame/--frames: %s has frames 0..%d; frame %d is not one of them",
                     o->scene_path, f->s->animation.frames - 1, o->frame_last);
            return -1;
        }
        f->first = o->frame_first;
        f->last = o->frame_last;
        f->step = o->frame_step;
    }
    if (o->movie) {
        tf_error("--movie: not available for an erosion film yet; assemble the frames' PNG "
                 "previews with ffmpeg");
        return -1;
    }
    f->pattern = o->output ? strdup(o->output) : tf_frame_default_pattern(o->scene_path);
    if (!f->pattern || !tf_frame_pattern_has_number(f->pattern)) {
        tf_error("-o %s: an erosion film needs a run of '#' in the output name for the frame "
                 "number (e.g. out/film.####.exr)", f->pattern ? f->pattern : "?");
        return -1;
    }
    return 0;
}

/* Frame k: its scene, its terrain, its still. */
static int render_frame(film *f, int k)
{
    char err[1024];
    tf_scene *fs = frame_scene(f, k, err, sizeof err);
    if (!fs) {
        tf_error("frame %d: %s", k, err);
        return 1;
    }
    if (wait_for_terrain(f, fs, k) != 0) {
        tf_scene_free(fs);
        return 1;
    }
    char *out = tf_frame_output_path(f->pattern, k);
    tf_render_opts fo = *f->o;
    fo.scene = fs; /* taken over by the render */
    fo.output = out;
    fo.frames_given = 0;
    tf_info("erosion film: frame %d of %d, the terrain after %d steps", k,
            f->s->animation.frames, k * f->s->animation.erosion_steps);
    int status = out ? tf_coordinator_run(&fo) : 1;
    if (!out)
        tf_scene_free(fs);
    free(out);
    return status;
}

int tf_erosion_film_run(const tf_render_opts *o, tf_scene *s)
{
    film f = {.o = o, .s = s, .eroder_status = 0};
    int status = 2;
    if (plan_frames(&f) != 0)
        goto out;
    tf_eroded_cache_beside(f.pattern);
    tf_erosion_checkpoints_enable(1);
    status = 1;
    if (start_eroder(&f) != 0)
        goto out;
    status = 0;
    for (int k = f.first; k <= f.last && status == 0; k += f.step)
        status = render_frame(&f, k);
out:
    stop_eroder(&f);
    free(f.pattern);
    tf_scene_free(s);
    return status;
}
