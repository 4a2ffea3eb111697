/* sock.c: see sock.h.  The only file that calls socket(), bind(), connect() or accept(). */
#include "linda/sock.h"
#include "clock.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>
#include "log.h"

/* Copy s[0..n) into dst (size cap) as a C string; -1 if it does not fit. */
static int copy_part(char *dst, size_t cap, const char *s, size_t n)
{
    if (n >= cap)
        return -1;
    memcpy(dst, s, n);
    dst[n] = 0;
    return 0;
}

int tf_split_hostport(const char *hostport, char *host, size_t hostlen, char *port,
                      size_t portlen, char *err, size_t errlen)
{
    const char *colon, *hs = hostport;
    size_t hn;
    if (hostport[0] == '[') {
        const char *close = strchr(hostport, ']');
        if (!close || close[1] != ':') {
            tf_seterr(err, errlen, "bad address '%s' (expected [ADDR]:PORT)", hostport);
            return -1;
        }
        hs = hostport + 1;
        hn = (size_t)(close - hs);
        colon = close + 1;
    } else {
        colon = strrchr(hostport, ':');
        if (!colon) {
            tf_seterr(err, errlen, "bad address '%s' (expected HOST:PORT)", hostport);
            return -1;
        }
        hn = (size_t)(colon - hostport);
    }
    const char *ps = colon + 1;
    size_t pn = strlen(ps);
    if (pn == 0 || strspn(ps, "0123456789") != pn || atol(ps) > 65535) {
        tf_seterr(err, errlen, "bad port in '%s'", hostport);
        return -1;
    }
    if (copy_part(host, hostlen, hs, hn) != 0 || copy_part(port, portlen, ps, pn) != 0) {
        tf_seterr(err, errlen, "address too long: '%.64s'", hostport);
        return -1;
    }
    return 0;
}

int tf_addr_is_loopback(const char *host)
{
    if (!host)
        return 0;
    if (strcasecmp(host, "localhost") == 0)
        return 1;
    struct in_addr a4;
    if (inet_pton(AF_INET, host, &a4) == 1)
        return (ntohl(a4.s_addr) >> 24) == 127;
    struct in6_addr a6;
    if (inet_pton(AF_INET6, host, &a6) == 1) {
        if (IN6_IS_ADDR_LOOPBACK(&a6))
            return 1;
        return IN6_IS_ADDR_V4MAPPED(&a6) && a6.s6_addr[12] == 127;
    }
    return 0;
}

int tf_listen_is_loopback(const char *spec)
{
    if (!strncmp(spec, "unix:", 5))
        return 1;
    char host[256], port[32], e[128];
    if (tf_split_hostport(spec, host, sizeof host, port, sizeof port, e, sizeof e))
        return 0;
    return tf_addr_is_loopback(host);
}

int tf_sock_set_nonblocking(int fd)
{
    int fl = fcntl(fd, F_GETFL);
    return fl < 0 ? -1 : fcntl(fd, F_SETFL, fl | O_NONBLOCK);
}

static void set_nodelay(int fd)
{
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
}

/* ---- listening ---- */

static int listen_unix(const char *path, char *err, size_t errlen)
{
    struct sockaddr_un sa = {.sun_family = AF_UNIX};
    if (strlen(path) >= sizeof sa.sun_path) {
        tf_seterr(err, errlen, "unix socket path too long: %.64s", path);
        return -1;
    }
    strcpy(sa.sun_path, path);
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISSOCK(st.st_mode))
        unlink(path); /* a stale socket from an earlier run */
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0 || bind(fd, (struct sockaddr *)&sa, sizeof sa) != 0 || listen(fd, 511) != 0) {
        tf_seterr(err, errlen, "cannot listen on unix:%s: %s", path, strerror(errno));
        if (fd >= 0)
            close(fd);
        return -1;
    }
    return fd;
}

/* Bind the first address getaddrinfo gives for host:port. */
static int listen_tcp(const char *spec, int *port_out, char *err, size_t errlen)
{
    char host[256], port[16];
    if (tf_split_hostport(spec, host, sizeof host, port, sizeof port, err, errlen) != 0)
        return -1;
    struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
                             .ai_flags = AI_PASSIVE | AI_NUMERICSERV}, *res, *ai;
    int rc = getaddrinfo(host[0] ? host : NULL, port, &hints, &res);
    if (rc != 0) {
        tf_seterr(err, errlen, "cannot listen on %s: %s", spec, gai_strerror(rc));
        return -1;
    }
    int fd = -1, saved = 0;
    for (ai = res; ai; ai = ai->ai_next) {
        fd = socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
        if (fd < 0)
            continue;
        int one = 1;
        setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        if (bind(fd, ai->ai_addr, ai->ai_addrlen) == 0 && listen(fd, 511) == 0)
            break;
        saved = errno;
        close(fd);
        fd = -1;
    }
    freeaddrinfo(res);
    if (fd < 0) {
        tf_seterr(err, errlen, "cannot listen on %s: %s", spec, strerror(saved ? saved : EINVAL));
        return -1;
    }
    if (port_out) {
        struct sockaddr_storage ss;
        socklen_t sl = sizeof ss;
        getsockname(fd, (struct sockaddr *)&ss, &sl);
        *port_out = ntohs(ss.ss_family == AF_INET6 ? ((struct sockaddr_in6 *)&ss)->sin6_port
                                                   : ((struct sockaddr_in *)&ss)->sin_port);
    }
    return fd;
}

/* "fd:N": a listening TCP socket inherited from the parent (a standing farm binds its jobs'
 * ports itself, so no other process can take one between choosing it and listening). */
static int listen_inherited(const char *num, int *port_out, char *err, size_t errlen)
{
    char *end;
    long fd = strtol(num, &end, 10);
    int on = 0;
    socklen_t ol = sizeof on;
    if (end == num || *end || fd < 3 || fd > 65535 ||
        getsockopt((int)fd, SOL_SOCKET, SO_ACCEPTCONN, &on, &ol) || !on)
        return tf_seterr(err, errlen, "listen fd:%s: not an inherited listening socket", num);
    fcntl((int)fd, F_SETFD, FD_CLOEXEC);
    tf_sock_set_nonblocking((int)fd);
    struct sockaddr_storage ss;
    socklen_t sl = sizeof ss;
    if (port_out && getsockname((int)fd, (struct sockaddr *)&ss, &sl) == 0)
        *port_out = ntohs(ss.ss_family == AF_INET6 ? ((struct sockaddr_in6 *)&ss)->sin6_port
                                                   : ((struct sockaddr_in *)&ss)->sin_port);
    return (int)fd;
}

int tf_sock_listen(const char *spec, int *port_out, char *err, size_t errlen)
{
    if (port_out)
        *port_out = 0;
    if (strncmp(spec, "unix:", 5) == 0)
        return listen_unix(spec + 5, err, errlen);
    if (strncmp(spec, "fd:", 3) == 0)
        return listen_inherited(spec + 3, port_out, err, errlen);
    return listen_tcp(spec, port_out, err, errlen);
}

/* ---- connecting ---- */

/* Non-blocking connect to one address with a deadline; returns the (blocking) fd or -1. */
static int connect_one(int family, const struct sockaddr *sa, socklen_t len, int64_t deadline,
                       int *err_out)
{
    int fd = socket(family, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) {
        *err_out = errno;
        return -1;
    }
    if (connect(fd, sa, len) != 0 && errno != EINPROGRESS) {
        *err_out = errno;
        close(fd);
        return -1;
    }
    struct pollfd p = {.fd = fd, .events = POLLOUT};
    int left = (int)(deadline - tf_now_ms());
    int pr = left > 0 ? poll(&p, 1, left) : 0;
    int soerr = 0;
    socklen_t sl = sizeof soerr;
    if (pr <= 0) {
        *err_out = pr == 0 ? ETIMEDOUT : errno;
        close(fd);
        return -1;
    }
    getsockopt(fd, SOL_SOCKET, SO_ERROR, &soerr, &sl);
    if (soerr) {
        *err_out = soerr;
        close(fd);
        return -1;
    }
    fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) & ~O_NONBLOCK);
    if (family != AF_UNIX)
        set_nodelay(fd);
    return fd;
}

int tf_sock_connect(const char *spec, int64_t deadline_ms, char *err, size_t errlen)
{
    int e = 0;
    if (strncmp(spec, "unix:", 5) == 0) {
        struct sockaddr_un sa = {.sun_family = AF_UNIX};
        if (strlen(spec + 5) >= sizeof sa.sun_path) {
            tf_seterr(err, errlen, "unix socket path too long");
            return -1;
        }
        strcpy(sa.sun_path, spec + 5);
        int fd = connect_one(AF_UNIX, (struct sockaddr *)&sa, sizeof sa, deadline_ms, &e);
        if (fd < 0)
            tf_seterr(err, errlen, "cannot connect to %s: %s", spec, strerror(e));
        return fd;
    }
    char host[256], port[16];
    if (tf_split_hostport(spec, host, sizeof host, port, sizeof port, err, errlen) != 0)
        return -1;
    struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
                             .ai_flags = AI_NUMERICSERV}, *res, *ai;
    int rc = getaddrinfo(host[0] ? host : "localhost", port, &hints, &res);
    if (rc != 0) {
        tf_seterr(err, errlen, "cannot resolve %s: %s", spec, gai_strerror(rc));
        return -1;
    }
    int fd = -1;
    for (ai = res; ai && fd < 0; ai = ai->ai_next)
        fd = connect_one(ai->ai_family, ai->ai_addr, ai->ai_addrlen, deadline_ms, &e);
    freeaddrinfo(res);
    if (fd < 0)
        tf_seterr(err, errlen, "cannot connect to %s: %s", spec, strerror(e));
    return fd;
}

/* ---- accepting ---- */

void tf_sock_format_peer(const struct sockaddr_storage *ss, char *buf, size_t len)
{
    char host[INET6_ADDRSTRLEN] = "?";
    if (ss->ss_family == AF_INET) {
        const struct sockaddr_in *a = (const void *)ss;
        inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
        snprintf(buf, len, "%s:%u", host, ntohs(a->sin_port));
    } else if (ss->ss_family == AF_INET6) {
        const struct sockaddr_in6 *a = (const void *)ss;
        inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
        snprintf(buf, len, "[%s]:%u", host, ntohs(a->sin6_port));
    } else {
        snprintf(buf, len, "unix");
    }
}

int tf_sock_accept(int listen_fd, char *peer, size_t peerlen)
{
    struct sockaddr_storage ss;
    socklen_t sl = sizeof ss;
    int fd = accept4(listen_fd, (struct sockaddr *)&ss, &sl, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0)
        return -1;
    tf_sock_format_peer(&ss, peer, peerlen);
    if (ss.ss_family != AF_UNIX)
        set_nodelay(fd);
    return fd;
}
