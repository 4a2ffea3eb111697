/* fuzz_scene.c: libFuzzer harness for the scene parser (common/scene*.c).  The input bytes are
 * scene text, as a networked worker would receive it.  Besides "no crash, leak or hang" it
 * checks two promises of scene.h on every input that parses:
 *   - the error contract: a rejected input yields one non-empty line with no newline;
 *   - the canonical form is a valid scene with the same canonical form and hash
 *     (parse(canonical(s)) == s), so the hash is a function of the struct alone.
 * Built by `make build/fuzz/fuzz_scene` (clang libFuzzer) and replayed over
 * tests/corpus/scene/ by `make test`. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void check_roundtrip(const tf_scene *s)
{
    char err[512];
    char *canon = tf_scene_canonical(s);
    if (!canon)
        abort();
    tf_scene *again = tf_scene_parse_text("<canonical>", canon, strlen(canon), err, sizeof err);
    if (!again)
        abort(); /* the canonical form must always parse */
    char *canon2 = tf_scene_canonical(again);
    if (!canon2 || strcmp(canon, canon2) != 0 || memcmp(s->hash, again->hash, 32) != 0)
        abort();
    free(canon2);
    free(canon);
    tf_scene_free(again);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char err[512];
    err[0] = '\0';
    tf_scene *s = tf_scene_parse_text("fuzz", (const char *)data, size, err, sizeof err);
    if (!s) {
        if (err[0] == '\0' || strchr(err, '\n'))
            abort(); /* every error is exactly one non-empty line */
        return 0;
    }
    check_roundtrip(s);
    tf_scene_free(s);
    return 0;
}
