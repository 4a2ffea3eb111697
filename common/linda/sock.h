/* sock.h: the sockets of the tuple space, in one place for the client and the server (in the
 * manner of Redis's anet.c).  An address is "HOST:PORT", "[V6ADDR]:PORT", ":PORT" (any host)
 * or "unix:PATH".  Every function reports failure as -1 with one line in err. */
#ifndef TF_SOCK_H
#define TF_SOCK_H

#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>

/* Split "HOST:PORT", "[V6ADDR]:PORT" or ":PORT" (host empty) into host and port strings. */
int tf_split_hostport(const char *hostport, char *host, size_t hostlen, char *port,
                      size_t portlen, char *err, size_t errlen);

/* 1 if host names the loopback interface (localhost, 127/8, ::1, ::ffff:127/104). */
int tf_addr_is_loopback(const char *host);
/* 1 if a listen address reaches only this machine: unix:PATH or a loopback host. */
int tf_listen_is_loopback(const char *spec);

/* A non-blocking, close-on-exec listening socket on spec (a stale unix socket file is
 * replaced; "fd:N" adopts the listening TCP socket N inherited from the parent).  *port_out (may be NULL) gets the bound TCP port, 0 for unix. */
int tf_sock_listen(const char *spec, int *port_out, char *err, size_t errlen);

/* Connect to spec, trying each address getaddrinfo gives, until the monotonic deadline
 * (tf_now_ms).  The socket returned is blocking, close-on-exec, with TCP_NODELAY. */
int tf_sock_connect(const char *spec, int64_t deadline_ms, char *err, size_t errlen);

/* accept4 one connection from a listening socket: non-blocking, close-on-exec, TCP_NODELAY;
 * its peer formatted into peer ("1.2.3.4:5", "[::1]:5", "unix").  -1 with errno set when there
 * is nothing to accept (EAGAIN) or on error. */
int tf_sock_accept(int listen_fd, char *peer, size_t peerlen);

/* Make fd non-blocking.  0 or -1. */
int tf_sock_set_nonblocking(int fd);

/* Format a socket address as accepted above. */
void tf_sock_format_peer(const struct sockaddr_storage *ss, char *buf, size_t len);

#endif
