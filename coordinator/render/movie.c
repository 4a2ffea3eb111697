/* movie.c: see movie.h.  The previews are linked into a private temporary directory as
 * 000000.png, 000001.png, ... (a frame range with a step, or one starting past 0, is then
 * still a plain image sequence for ffmpeg's image2 demuxer), ffmpeg runs with no shell between
 * (fork + execvp, stdin from /dev/null, its messages to a file quoted on failure), and the video
 * is renamed into place only once ffmpeg succeeded. */
#include "coordinator/render/movie.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "log.h"

static const char *extension(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    return dot && (!slash || dot > slash) ? dot + 1 : "";
}

int tf_movie_check_name(const char *path, char *err, size_t errlen)
{
    const char *ext = extension(path);
    if (!strcasecmp(ext, "mp4") || !strcasecmp(ext, "webm"))
        return 0;
    return tf_seterr(err, errlen, "--movie %s: expected a .mp4 or .webm file name", path);
}

int tf_movie_available(void)
{
    const char *path = getenv("PATH");
    if (!path)
        return 0;
    char buf[PATH_MAX];
    for (const char *p = path; *p;) {
        const char *colon = strchr(p, ':');
        size_t n = colon ? (size_t)(colon - p) : strlen(p);
        if (n > 0 && n + sizeof "/ffmpeg" < sizeof buf) {
            snprintf(buf, sizeof buf, "%.*s/ffmpeg", (int)n, p);
            if (access(buf, X_OK) == 0)
                return 1;
        }
        p += n + (colon ? 1 : 0);
        if (!colon)
            break;
    }
    return 0;
}

/* The last non-empty line of a file, for an error message. */
static void last_line(const char *path, char *out, size_t len)
{
    snprintf(out, len, "no message");
    FILE *f = fopen(path, "r");
    if (!f)
        return;
    char line[512];
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\r\n")] = '\0';
        if (line[0])
            snprintf(out, len, "%.200s", line);
    }
    fclose(f);
}

/* Frame i's PNG as dir/NNNNNN.png (a symbolic link), the numbered names ffmpeg reads.  0, or -1
 * with err. */
static int link_frame(const char *dir, int i, const char *png, char *err, size_t errlen)
{
    char link[PATH_MAX], target[PATH_MAX];
    snprintf(link, sizeof link, "%s/%06d.png", dir, i);
    if (!realpath(png, target) || symlink(target, link))
        return tf_seterr(err, errlen, "--movie: cannot use %s: %s", png, strerror(errno));
    return 0;
}

/* ffmpeg with argv, its output to the file `log`; its exit status (or -1: not started). */
static int run_ffmpeg(const char *const *argv, const char *log)
{
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0) {
        int null = open("/dev/null", O_RDONLY);
        int logfd = open(log, O_WRONLY | O_CREAT | O_TRUNC, 0600);
        if (null >= 0)
            dup2(null, 0);
        if (logfd >= 0) {
            dup2(logfd, 1);
            dup2(logfd, 2);
        }
        execvp("ffmpeg", (char *const *)argv);
        _exit(127);
    }
    int status;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
        ;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

/* The numbered frames in dir encoded into tmp at fps (H.264, or VP9 for .webm), even sides as
 * yuv420p needs.  0, or -1 with err (ffmpeg's last line; what it left at tmp removed). */
static int encode_frames(const char *dir, const char *path, const char *tmp, double fps,
                         char *err, size_t errlen)
{
    char log[PATH_MAX], pattern[PATH_MAX], rate[32];
    snprintf(log, sizeof log, "%s/ffmpeg.log", dir);
    snprintf(pattern, sizeof pattern, "%s/%%06d.png", dir);
    snprintf(rate, sizeof rate, "%.6g", fps);
    int webm = !strcasecmp(extension(path), "webm");
    const char *argv[] = {"ffmpeg", "-nostdin", "-hide_banner", "-loglevel", "error", "-y",
                          "-framerate", rate, "-i", pattern,
                          "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p",
                          "-c:v", webm ? "libvpx-vp9" : "libx264",
                          webm ? "-b:v" : "-crf", webm ? "0" : "18",
                          webm ? "-crf" : "-movflags", webm ? "32" : "+faststart",
                          tmp, NULL};
    int status = run_ffmpeg(argv, log);
    if (status < 0)
        return tf_seterr(err, errlen, "--movie: cannot start ffmpeg: %s", strerror(errno));
    if (status == 0)
        return 0;
    char why[256];
    last_line(log, why, sizeof why);
    remove(tmp);
    return tf_seterr(err, errlen, "--movie %s: ffmpeg failed: %s", path, why);
}

/* The temporary directory's links (the first `linked`) and log removed, then the directory. */
static void remove_workdir(const char *dir, int linked)
{
    char name[PATH_MAX];
    for (int i = 0; i < linked; i++) {
        snprintf(name, sizeof name, "%s/%06d.png", dir, i);
        unlink(name);
    }
    snprintf(name, sizeof name, "%s/ffmpeg.log", dir);
    unlink(name);
    rmdir(dir);
}

int tf_movie_make(const char *path, const char *const *pngs, int n, double fps, char *err,
                  size_t errlen)
{
    if (tf_movie_check_name(path, err, errlen))
        return -1;
    if (!tf_movie_available())
        return tf_seterr(err, errlen, "--movie %s: ffmpeg is not installed (apt-get install "
                         "ffmpeg); the frames and their PNG previews are written", path);
    if (n < 1)
        return tf_seterr(err, errlen, "--movie %s: no frames", path);
    char dir[] = "/tmp/terrafarm-movie.XXXXXX";
    if (!mkdtemp(dir))
        return tf_seterr(err, errlen, "--movie: cannot make a temporary directory: %s",
                         strerror(errno));
    int linked = 0, rc = -1;
    while (linked < n && link_frame(dir, linked, pngs[linked], err, errlen) == 0)
        linked++;
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s.tmp.%s", path, extension(path));
    if (linked == n && encode_frames(dir, path, tmp, fps, err, errlen) == 0) {
        rc = rename(tmp, path);
        if (rc != 0) {
            tf_seterr(err, errlen, "--movie %s: cannot rename into place: %s", path,
                      strerror(errno));
            remove(tmp);
        }
    }
    remove_workdir(dir, linked);
    return rc;
}
