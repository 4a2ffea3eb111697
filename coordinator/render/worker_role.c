/* worker_role.c: the worker role's rules (see worker_role.h); the guard is the supervisor's
 * tf_supervisor_admit, which knows leases and worker ids. */
#include "coordinator/render/worker_role.h"

#include "farmproto.h"

static const ts_cap_rule worker_rules[] = {
    {TS_CAP_RD, TF_TAG_SCENE, TF_SCENE_FIELDS, 0, NULL},
    {TS_CAP_RD, "heightmap", 4, 0, NULL},       /* generator = file: heightmap_tuples.h */
    {TS_CAP_RD, "heightmap_chunk", 3, 0, NULL},
    {TS_CAP_RD, "eroded", 4, 0, NULL},          /* [erosion]: the eroded terrain, the same way */
    {TS_CAP_RD, "eroded_chunk", 3, 0, NULL},
    {TS_CAP_IN, TF_TAG_NEXT_WORKER, TF_NEXT_WORKER_FIELDS, 1, tf_supervisor_admit},
    {TS_CAP_OUT, TF_TAG_HELLO, TF_HELLO_FIELDS, 1, tf_supervisor_admit},
    {TS_CAP_IN, TF_TAG_TASK, TF_TASK_FIELDS, 0, tf_supervisor_admit},
    {TS_CAP_OUT, TF_TAG_TASK, TF_TASK_FIELDS, 0, tf_supervisor_admit},
    {TS_CAP_OUT, TF_TAG_RESULT, TF_RESULT_FIELDS, 0, tf_supervisor_admit},
    {TS_CAP_OUT, TF_TAG_FAILED, TF_FAILED_FIELDS, 0, tf_supervisor_admit},
};

/* A result's chunks never exceed their unpacked size (farmproto.h: 1 <= packed <= unpacked),
 * at most 24 bytes a pixel (all channels FLOAT); room beyond that for the index, the preview
 * share and the other fields. */
#define RESULT_BYTES_PER_PIXEL 24u
#define RESULT_HEADROOM (64u * 1024u)

void tf_worker_role_init(ts_role *role, tf_supervisor *sup, const tf_tasks *tasks)
{
    size_t largest = (size_t)tasks->tw * (size_t)tasks->th * RESULT_BYTES_PER_PIXEL;
    role->name = "worker";
    role->rules = worker_rules;
    role->nrules = (int)(sizeof worker_rules / sizeof worker_rules[0]);
    role->guard_ctx = sup;
    role->max_tuple_bytes = largest + largest / 8 + RESULT_HEADROOM;
}
