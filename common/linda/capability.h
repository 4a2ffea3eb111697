/* capability.h: who may do what in a tuple space.  Linda trusts every process in the space; a
 * farm spread over machines cannot, so every server connection (tsserver.h) carries a role,
 * and every request it makes (out, in/inp, rd/rdp) is checked against that role before the
 * space sees it.  The in-process client (the supervisor calls ts_space directly) is outside
 * this: it is privileged by construction.
 *
 * A role is a list of rules.  A rule names the operations it grants (TS_CAP_OUT, TS_CAP_IN
 * for in and inp, TS_CAP_RD for rd and rdp), the tuple name (the first field, which must be an
 * actual string in the tuple or template), the arity, an optional cap on how many times one
 * connection may use it, and an optional guard: a function of the role's owner that looks at
 * the tuple and the connection and answers allow / refuse / discard (e.g. the farm checks that
 * a result answers a task this connection holds; see coordinator/render/worker_role.c).  The first
 * rule whose ops, name and arity match decides; a request no rule grants is refused.
 *
 * A refused request gets an ERROR reply for its request id and changes nothing in the space;
 * the server logs one rate-limited line naming the peer and the reason.  A discarded out gets
 * an OK reply but is not stored (a late duplicate result: harmless, and the worker goes on).
 * A role may also bound the size of one tuple (and so of one frame) its connections send. */
#ifndef TF_CAPABILITY_H
#define TF_CAPABILITY_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"

enum { TS_CAP_OUT = 1, TS_CAP_IN = 2, TS_CAP_RD = 4 };

typedef enum { TS_CAP_ALLOW = 0, TS_CAP_REFUSE = 1, TS_CAP_DISCARD = 2 } ts_cap_verdict;

/* op: TS_CAP_OUT, TS_CAP_IN or TS_CAP_RD; blocking says whether an in/rd may wait.  On
 * TS_CAP_REFUSE, why receives one line (no peer: the server adds it). */
typedef ts_cap_verdict (*ts_cap_guard)(void *ctx, uint64_t conn, int op, int blocking,
                                       const tf_tuple *t, char *why, size_t whylen);

typedef struct ts_cap_rule {
    unsigned ops;       /* TS_CAP_* bits this rule grants */
    const char *name;   /* tuple name (first field) */
    int arity;          /* number of fields */
    int max_uses;       /* per connection; 0: unlimited */
    ts_cap_guard guard; /* NULL: the rule alone decides */
} ts_cap_rule;

#define TS_CAP_MAX_RULES 16

typedef struct ts_role {
    const char *name;           /* for logs: "worker" */
    const ts_cap_rule *rules;   /* nrules <= TS_CAP_MAX_RULES */
    int nrules;
    void *guard_ctx;            /* passed to every guard */
    size_t max_tuple_bytes;     /* largest tuple (encoded) one request may carry; 0: no limit
                                   beyond the frame size */
} ts_role;

/* What a connection has used of its role (zero-initialised with the connection). */
typedef struct ts_cap_usage {
    int uses[TS_CAP_MAX_RULES];
} ts_cap_usage;

/* Check one request.  role NULL: privileged, everything is allowed.  op is a TS_CAP_* value.
 * Counts the use of the deciding rule when the verdict is ALLOW or DISCARD. */
ts_cap_verdict ts_cap_check(const ts_role *role, ts_cap_usage *usage, uint64_t conn, int op,
                            int blocking, const tf_tuple *t, char *why, size_t whylen);

/* "out", "in", "rd" for logs. */
const char *ts_cap_op_name(int op);

#endif
