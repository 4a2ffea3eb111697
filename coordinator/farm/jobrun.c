/* jobrun.c: see jobrun.h. */
#include "coordinator/farm/jobrun.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cachefile.h"
#include "farm_keys.h"
#include "linda/sock.h"
#include "log.h"
#include "scene.h"

int tf_job_path(const char *state_dir, int64_t id, const char *name, char *out, size_t n)
{
    int k = snprintf(out, n, "%s/jobs/%lld%s%s", state_dir, (long long)id, name ? "/" : "",
                     name ? name : "");
    return k > 0 && (size_t)k < n ? 0 : -1;
}

/* Write len bytes to dir/name atomically (a temporary file renamed over it), mode 0600. */
static int write_file(const char *dir, const char *name, const void *data, size_t len,
                      char *err, size_t errlen)
{
    char path[4096], tmp[4200];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0)
        return tf_seterr(err, errlen, "%s: cannot create: %s", tmp, strerror(errno));
    const char *p = data;
    size_t left = len;
    while (left) {
        ssize_t w = write(fd, p, left);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0) {
            int e = errno;
            close(fd);
            unlink(tmp);
            return tf_seterr(err, errlen, "%s: cannot write: %s", tmp, strerror(e));
        }
        p += w;
        left -= (size_t)w;
    }
    if (fsync(fd) || close(fd) || rename(tmp, path)) {
        unlink(tmp);
        return tf_seterr(err, errlen, "%s: cannot write: %s", path, strerror(errno));
    }
    return 0;
}

/* The job's copy of a height map: "heightmap" and the submitted name's extension, if a plain
 * one (decoders choose by content; the extension only helps a person). */
static void heightmap_file_name(const char *submitted, char *out, size_t n)
{
    const char *dot = submitted ? strrchr(submitted, '.') : NULL;
    size_t k = dot ? strlen(dot + 1) : 0;
    int plain = k > 0 && k <= 8;
    for (size_t i = 0; plain && i < k; i++)
        plain = (dot[1 + i] >= 'a' && dot[1 + i] <= 'z') || (dot[1 + i] >= '0' && dot[1 + i] <= '9');
    snprintf(out, n, "heightmap%s%s", plain ? "." : "", plain ? dot + 1 : "");
}

/* The scene the render reads: the submitted scene's canonical form, its height map path (if
 * any) replaced by the job's own copy, so the render opens only files of the job's folder. */
static char *rewritten_scene(const tf_job *j, const tf_job_content *c, const char *hm_name,
                             char *err, size_t errlen)
{
    tf_scene *s = tf_scene_parse_text(j->name, c->scene, c->scene_len, err, errlen);
    if (!s)
        return NULL;
    if (s->terrain.generator == TF_GEN_FILE)
        snprintf(s->terrain.file_path, sizeof s->terrain.file_path, "%s", hm_name);
    char *text = tf_scene_canonical(s);
    tf_scene_free(s);
    if (!text)
        tf_seterr(err, errlen, "out of memory");
    return text;
}

int tf_jobrun_prepare(const char *state_dir, const tf_job *j, const tf_job_content *c,
                      const uint8_t farm_key[32], const char *submit_token, char *err,
                      size_t errlen)
{
    char dir[4096], hm[64], secret[TF_FARM_TOKEN_HEX];
    if (tf_job_path(state_dir, j->id, NULL, dir, sizeof dir))
        return tf_seterr(err, errlen, "%s: path too long", state_dir);
    if (tf_make_private_dirs(dir))
        return tf_seterr(err, errlen, "%s: cannot create the job's folder: %s", dir,
                         strerror(errno));
    heightmap_file_name(c->heightmap_name, hm, sizeof hm);
    char *scene = rewritten_scene(j, c, hm, err, errlen);
    if (!scene)
        return -1;
    int rc = write_file(dir, "job.scene", scene, strlen(scene), err, errlen);
    free(scene);
    if (!rc && c->heightmap)
        rc = write_file(dir, hm, c->heightmap, c->heightmap_len, err, errlen);
    if (!rc && tf_farm_job_secret(farm_key, j->id, j->nonce, secret))
        rc = tf_seterr(err, errlen, "cannot derive job %lld's secret", (long long)j->id);
    if (!rc)
        rc = write_file(dir, "secret", secret, 64, err, errlen);
    if (!rc && submit_token)
        rc = write_file(dir, "farm-token", submit_token, strlen(submit_token), err, errlen);
    return rc;
}

static void free_argv(char **av)
{
    for (size_t i = 0; av && av[i]; i++)
        free(av[i]);
    free(av);
}

/* A command line: the fixed arguments, then the job's options (a JSON array of strings),
 * as malloc'd strings in a NULL-terminated array (freed by free_argv), or NULL. */
static char **argv_of(const char *const *fixed, size_t nfixed, const char *options)
{
    json_t *opts = json_loads(options, 0, NULL);
    size_t nopt = json_array_size(opts), k = 0;
    char **av = calloc(nfixed + nopt + 1, sizeof *av);
    for (size_t i = 0; av && i < nfixed; i++)
        av[k++] = strdup(fixed[i]);
    for (size_t i = 0; av && i < nopt; i++)
        av[k++] = strdup(json_string_value(json_array_get(opts, i)));
    json_decref(opts);
    for (size_t i = 0; av && i < k; i++)
        if (!av[i]) { /* out of memory: no half command line */
            for (size_t m = i + 1; m < k; m++)
                free(av[m]);
            free_argv(av);
            return NULL;
        }
    return av;
}

/* argv of a paint job, run in its folder (so its page names no farm path). */
static char **paint_argv(const char *exe, const tf_jobrun_where *at, const char *options,
                         int listen_fd, int http_fd)
{
    char lfd[32], hfd[32], farm[300];
    snprintf(lfd, sizeof lfd, "fd:%d", listen_fd);
    snprintf(hfd, sizeof hfd, "fd:%d", http_fd);
    snprintf(farm, sizeof farm, strchr(at->host, ':') ? "[%s]:%d" : "%s:%d", at->host,
             at->api_port);
    const char *const fixed[] = {exe, "paint", "job.scene", "-j", "0", "--listen", lfd,
                                 "--secret-file", "secret", "--http", hfd, "-o", "painted.exr",
                                 "--save", "edited.scene", "--farm", farm, "--farm-token-file",
                                 "farm-token"};
    return argv_of(fixed, sizeof fixed / sizeof *fixed, options);
}

/* argv of the render. */
static char **render_argv(const char *exe, const char *dir, const tf_job *j, const char *options,
                          int listen_fd, int http_fd)
{
    char lfd[32], hfd[32], scene[4200], out[4200], secret[4200], stats[4200];
    snprintf(lfd, sizeof lfd, "fd:%d", listen_fd);
    snprintf(hfd, sizeof hfd, "fd:%d", http_fd);
    snprintf(scene, sizeof scene, "%s/job.scene", dir);
    snprintf(out, sizeof out, "%s/%s", dir, j->output);
    snprintf(secret, sizeof secret, "%s/secret", dir);
    snprintf(stats, sizeof stats, "%s/stats.json", dir);
    const char *const fixed[] = {exe, "render", scene, "-o", out, "-j", "0", "--listen", lfd,
                                 "--secret-file", secret, "--http", hfd, "--resume", "--stats",
                                 stats};
    return argv_of(fixed, sizeof fixed / sizeof *fixed, options);
}

/* In the child, between fork and exec: only async-signal-safe calls. */
static void exec_render(char **av, const char *dir, pid_t farm, int listen_fd, int http_fd,
                        int lock_fd, int log_fd)
{
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != farm || chdir(dir)) /* the farm died before the line above */
        _exit(127);
    flock(lock_fd, LOCK_EX); /* wait for an older render of this job to be gone */
    int devnull = open("/dev/null", O_RDWR);
    dup2(devnull, 0);
    dup2(log_fd, 1);
    dup2(log_fd, 2);
    fcntl(listen_fd, F_SETFD, 0);
    fcntl(http_fd, F_SETFD, 0);
    fcntl(lock_fd, F_SETFD, 0);
    signal(SIGPIPE, SIG_DFL);
    execv(av[0], av);
    _exit(127);
}

pid_t tf_jobrun_start(const char *exe, const char *state_dir, const tf_job *j,
                      const char *options, tf_jobrun_where *at, char *err, size_t errlen)
{
    char dir[4096], spec[300], path[4200];
    tf_job_path(state_dir, j->id, NULL, dir, sizeof dir);
    snprintf(spec, sizeof spec, strchr(at->host, ':') ? "[%s]:0" : "%s:0", at->host);
    int lfd = tf_sock_listen(spec, &at->port, err, errlen);
    if (lfd < 0)
        return -1;
    int hfd = tf_sock_listen(spec, &at->http_port, err, errlen);
    if (hfd < 0) {
        close(lfd);
        return -1;
    }
    snprintf(path, sizeof path, "%s/lock", dir);
    int lock_fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    snprintf(path, sizeof path, "%s/render.log", dir);
    int log_fd = open(path, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    char **av = tf_job_is_paint(j) ? paint_argv(exe, at, options, lfd, hfd)
                                           : render_argv(exe, dir, j, options, lfd, hfd);
    pid_t pid = -1, farm = getpid();
    if (lock_fd < 0 || log_fd < 0 || !av)
        tf_seterr(err, errlen, "%s: cannot prepare the render: %s", dir, strerror(errno));
    else if ((pid = fork()) == 0)
        exec_render(av, dir, farm, lfd, hfd, lock_fd, log_fd);
    else if (pid < 0)
        tf_seterr(err, errlen, "cannot start the render of job %lld: fork: %s",
                  (long long)j->id, strerror(errno));
    free_argv(av);
    close(lfd);
    close(hfd);
    if (lock_fd >= 0)
        close(lock_fd);
    if (log_fd >= 0)
        close(log_fd);
    return pid;
}

/* The job's folder is the farm's business: "STATE/jobs/ID/out.exr" is shown as "out.exr". */
static void strip_job_folder(const char *state_dir, int64_t id, char *text)
{
    char dir[4200];
    if (tf_job_path(state_dir, id, "", dir, sizeof dir))
        return;
    size_t k = strlen(dir);
    for (char *p = strstr(text, dir); p; p = strstr(p, dir))
        memmove(p, p + k, strlen(p + k) + 1);
}

void tf_jobrun_last_error(const char *state_dir, int64_t id, char *out, size_t n)
{
    char path[4200], line[1024];
    out[0] = 0;
    if (tf_job_path(state_dir, id, "render.log", path, sizeof path))
        return;
    FILE *f = fopen(path, "r");
    if (!f)
        return;
    while (fgets(line, sizeof line, f))
        if (line[0] && line[0] != '\n') {
            line[strcspn(line, "\n")] = 0;
            snprintf(out, n, "%s", line);
        }
    fclose(f);
    strip_job_folder(state_dir, id, out);
}
