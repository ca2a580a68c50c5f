/* Thread-local error messages and checked size arithmetic. */
#include "gen3d/base.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static _Thread_local char g_msg[1024];

static const char *const g_status_names[G3D_STATUS_COUNT] = {
    "ok", "io", "format", "unsupported", "argument", "mismatch", "memory", "model", "internal", "cancelled",
};

const char *g3d_status_name(g3d_status s)
{
    if ((int)s < 0 || s >= G3D_STATUS_COUNT) return "unknown";
    return g_status_names[s];
}

g3d_status g3d__error_set(g3d_status code, const char *where, const char *fmt, ...)
{
    char body[900];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(body, sizeof body, fmt, ap);
    va_end(ap);
    if (where && getenv("G3D_ERROR_WHERE"))
        snprintf(g_msg, sizeof g_msg, "%s [%.100s]", body, where);
    else
        snprintf(g_msg, sizeof g_msg, "%s", body);
    return code;
}

const char *g3d_error_message(void) { return g_msg; }

void g3d_error_prefix(const char *prefix)
{
    char tmp[sizeof g_msg];
    if (!prefix || !*prefix) return;
    snprintf(tmp, sizeof tmp, "%.200s: %.800s", prefix, g_msg);
    memcpy(g_msg, tmp, sizeof g_msg);
}

void g3d_error_clear(void) { g_msg[0] = 0; }

int g3d_size_mul(size_t a, size_t b, size_t *out)
{
    if (a != 0 && b > SIZE_MAX / a) return 0;
    *out = a * b;
    return 1;
}

int g3d_size_mul3(size_t a, size_t b, size_t c, size_t *out)
{
    size_t ab;
    return g3d_size_mul(a, b, &ab) && g3d_size_mul(ab, c, out);
}

void *g3d_calloc(size_t n, size_t size, const char *what)
{
    size_t total;
    void *p;
    if (!g3d_size_mul(n, size, &total)) {
        G3D_ERR(G3D_ERR_NOMEM, "%s: size overflow (%zu x %zu bytes)", what, n, size);
        return NULL;
    }
    p = calloc(total ? total : 1, 1);
    if (!p) G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory (%zu bytes)", what, total);
    return p;
}
