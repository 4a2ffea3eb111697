/* outbox.c: the memory a forked worker shares with its coordinator (see outbox.h). */
#include "linda/outbox.h"

#include <errno.h>
#include <string.h>
#include <sys/mman.h>

#include "log.h"

int tf_outbox_create(tf_outbox *ob, char *err, size_t errlen)
{
    void *p = mmap(NULL, TF_OUTBOX_BYTES, PROT_READ | PROT_WRITE,
                   MAP_SHARED | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) {
        ob->base = NULL;
        ob->size = 0;
        return tf_seterr(err, errlen, "mapping a worker's outbox: %s", strerror(errno));
    }
    ob->base = p;
    ob->size = TF_OUTBOX_BYTES;
    return 0;
}

void tf_outbox_keep_from_later_forks(const tf_outbox *ob)
{
    if (ob->base)
        madvise(ob->base, ob->size, MADV_DONTFORK);
}

void tf_outbox_release(tf_outbox *ob)
{
    if (ob->base)
        munmap(ob->base, ob->size);
    ob->base = NULL;
    ob->size = 0;
}
