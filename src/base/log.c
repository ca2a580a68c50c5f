/* Process-wide log sink with a level filter (stderr by default). */
#include "gen3d/base.h"

#include <stdio.h>

static g3d_log_fn g_log_fn;
static void *g_log_user;
static g3d_log_level g_log_level = G3D_LOG_INFO;

void g3d_log_set(g3d_log_fn fn, void *user)
{
    g_log_fn = fn;
    g_log_user = user;
}

void g3d_log_set_level(g3d_log_level level) { g_log_level = level; }
g3d_log_level g3d_log_get_level(void) { return g_log_level; }

void g3d_log(g3d_log_level level, const char *fmt, ...)
{
    static const char *const tag[] = {"error", "warning", "info", "debug"};
    char msg[2048];
    va_list ap;
    if (level > g_log_level) return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (g_log_fn)
        g_log_fn(g_log_user, level, msg);
    else if (level == G3D_LOG_INFO)
        fprintf(stderr, "%s\n", msg);
    else
        fprintf(stderr, "gen3d: %s: %s\n", tag[level], msg);
}
