/* exrerror.c: the error text of the OpenEXR output (exrinternal.h).  OpenEXRCore reports
 * details through a callback on the failing thread; we keep the last one per thread (never
 * printed) and append it to our own one-line messages "PATH: what: detail". */
#include "image/exrinternal.h"

#include <stdio.h>

#include "log.h"

static _Thread_local char last_exr_message[200];

void tf_exr_remember_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    snprintf(last_exr_message, sizeof last_exr_message, "%s (%s)", msg ? msg : "",
             exr_get_error_code_as_string(code));
}

void tf_exr_clear_error(void) { last_exr_message[0] = '\0'; }

void tf_exr_set_error(char *err, size_t errlen, const char *path, const char *what,
                      exr_result_t rv)
{
    if (!err || errlen == 0)
        return;
    if (rv != EXR_ERR_SUCCESS && last_exr_message[0])
        tf_seterr(err, errlen, "%s: %s: %s", path, what, last_exr_message);
    else if (rv != EXR_ERR_SUCCESS)
        tf_seterr(err, errlen, "%s: %s: %s", path, what, exr_get_default_error_message(rv));
    else
        tf_seterr(err, errlen, "%s: %s", path, what);
}
