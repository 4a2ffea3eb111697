/* capability.c: the rule check of capability.h. */
#include "linda/capability.h"

#include <string.h>

#include "log.h"

const char *ts_cap_op_name(int op)
{
    return op == TS_CAP_OUT ? "out" : op == TS_CAP_IN ? "in" : op == TS_CAP_RD ? "rd" : "?";
}

ts_cap_verdict ts_cap_check(const ts_role *role, ts_cap_usage *usage, uint64_t conn, int op,
                            int blocking, const tf_tuple *t, char *why, size_t whylen)
{
    if (!role)
        return TS_CAP_ALLOW;
    if (role->max_tuple_bytes && tf_tuple_bytes(t) > role->max_tuple_bytes) {
        tf_seterr(why, whylen, "%s of a %zu-byte tuple: the %s role allows at most %zu",
                  ts_cap_op_name(op), tf_tuple_bytes(t), role->name, role->max_tuple_bytes);
        return TS_CAP_REFUSE;
    }
    const char *name = NULL;
    if (t->nfields > 0 && t->f[0].type == TF_FIELD_STRING && !t->f[0].formal)
        name = (const char *)t->f[0].v.bytes.ptr;
    if (!name) {
        tf_seterr(why, whylen, "%s without a tuple name: not allowed to a %s", ts_cap_op_name(op),
                  role->name);
        return TS_CAP_REFUSE;
    }
    for (int i = 0; i < role->nrules && i < TS_CAP_MAX_RULES; i++) {
        const ts_cap_rule *r = &role->rules[i];
        if (!(r->ops & (unsigned)op) || r->arity != t->nfields || strcmp(r->name, name))
            continue;
        if (r->max_uses > 0 && usage->uses[i] >= r->max_uses) {
            tf_seterr(why, whylen, "%s (\"%s\", ...) more than %d time%s: not allowed to a %s",
                      ts_cap_op_name(op), name, r->max_uses, r->max_uses == 1 ? "" : "s",
                      role->name);
            return TS_CAP_REFUSE;
        }
        ts_cap_verdict v = TS_CAP_ALLOW;
        if (r->guard)
            v = r->guard(role->guard_ctx, conn, op, blocking, t, why, whylen);
        if (v != TS_CAP_REFUSE)
            usage->uses[i]++;
        return v;
    }
    tf_seterr(why, whylen, "%s (\"%.40s\", %d fields): not allowed to a %s", ts_cap_op_name(op),
              name, t->nfields, role->name);
    return TS_CAP_REFUSE;
}
