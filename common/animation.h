/* animation.h: a scene's [animation] section (scenes/README.md): a frame count, a frame rate,
 * camera keys and sun keys, and the splines that give the camera and the sun of any frame.
 *
 * The parser (scene_values.c, scene_check.c) fills a tf_animation from the file and calls
 * tf_animation_check; the coordinator and every worker then ask for the camera of frame f
 * with tf_scene_apply_frame (scene.h, scene_frame.c), a pure function of the parsed keys and f
 * (plain double arithmetic, no FMA contraction), so a frame's pixels are the same whichever
 * process, machine or run computes them.
 *
 * The splines.
 *   Camera position and look_at: each a centripetal Catmull-Rom curve (alpha = 1/2, Yuksel,
 *   Schaefer & Keyser 2011) through its key points: knot k+1 = knot k + sqrt(|P(k+1) - P(k)|)
 *   (at least 1e-3 of the largest such step, so repeated points stay well defined), with
 *   phantom end points mirrored through the end keys (P(-1) = 2 P(0) - P(1)).  The curve is
 *   evaluated by the Barry-Goldman pyramid; it is C1 in its knot parameter u, has no cusp or
 *   self-intersection within a segment, and passes through every key at its knot.  The frame
 *   number reaches u through a monotone C1 cubic u(f) through the points (key frame, knot)
 *   (piecewise cubic Hermite with Fritsch-Butland slopes), so the camera is at key k exactly
 *   at key k's frame, never moves backwards along the path, and its velocity d/df P(u(f)) =
 *   P'(u) u'(f) is continuous.
 *   fov, up and the sun's azimuth/elevation: Catmull-Rom with the key frames themselves as
 *   knots (non-uniform, C1 in the frame number), mirrored end points likewise.
 *   Frames before the first key or after the last hold the end key's values (the checks below
 *   require the first key at frame 0 and the last at or after the last frame, so a render
 *   never reaches them). */
#ifndef TF_ANIMATION_H
#define TF_ANIMATION_H

#include <stddef.h>
#include "vec.h"

#define TF_ANIM_MAX_KEYS 256      /* camera keys, and sun keys, per scene */
#define TF_ANIM_MAX_FRAMES 100000 /* frames per scene */

typedef struct tf_camera_key {
    int frame;
    tf_vec3 position, look_at, up;
    double fov_deg;
    int line;            /* scene file line, for messages (not part of the scene's identity) */
} tf_camera_key;

typedef struct tf_sun_key {
    int frame;
    double azimuth_deg, elevation_deg;
    int line;
} tf_sun_key;

typedef struct tf_animation {
    int frames;          /* 0: a still scene (no [animation] section) */
    double fps;          /* frame rate of --movie */
    int ncamera, nsun;   /* 0 = that part is not animated: the [camera] / [sun] values hold */
    int erosion_steps;   /* > 0: an erosion film: frame k shows the terrain after k times this
                          * many steps of [erosion] (coordinator/erosion/erosion_film.h) */
    tf_camera_key camera[TF_ANIM_MAX_KEYS];
    tf_sun_key sun[TF_ANIM_MAX_KEYS];
} tf_animation;

/* The camera of frame f (a.ncamera >= 2, keys checked).  up is not normalised. */
void tf_animation_camera_at(const tf_animation *a, double f, tf_vec3 *position,
                            tf_vec3 *look_at, tf_vec3 *up, double *fov_deg);
/* The sun of frame f (a.nsun >= 2, keys checked). */
void tf_animation_sun_at(const tf_animation *a, double f, double *azimuth_deg,
                         double *elevation_deg);

/* Check the keys once they are all read: enough of them, in increasing frame order, covering
 * frames 0 .. frames-1, and every frame's camera well defined (look_at != position, up not
 * parallel to the view, fov in range for the camera kind: pinhole below 180, panorama up to
 * 360) and every frame's sun elevation within -90..90.  0, or -1 with *line set to the scene
 * line to blame and `what` to "key: what is wrong" (one line). */
int tf_animation_check(const tf_animation *a, int pinhole, int *line, char *what, size_t len);

/* The scene line of the camera key that starts frame f's segment (for messages). */
int tf_animation_camera_line(const tf_animation *a, int f);

#endif
