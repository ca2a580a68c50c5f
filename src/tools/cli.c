/* The option-table parser, the common flags and error printing shared by all commands. */
#include "cli.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <omp.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static g3d_progress_term g_term;
static g3d_progress g_progress;

void g3d_cli_common_init(g3d_cli_common *c)
{
    memset(c, 0, sizeof *c);
}

void g3d_cli_common_apply(g3d_cli_common *c)
{
    if (c->quiet) g3d_log_set_level(G3D_LOG_WARN);
    if (c->verbose) g3d_log_set_level(G3D_LOG_DEBUG);
    if (c->threads > 0) omp_set_num_threads(c->threads);
    if (c->seed < 0) {
        /* Random seed from the clock and pid; printed below so the run can be repeated. */
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        uint64_t x = (uint64_t)ts.tv_nsec ^ ((uint64_t)ts.tv_sec << 20) ^ ((uint64_t)getpid() << 40);
        x ^= x >> 33; x *= 0xff51afd7ed558ccdULL; x ^= x >> 33;
        c->seed = (int64_t)(x & 0x7fffffff);
    }
    g3d_log(G3D_LOG_INFO, "seed: %" PRId64, c->seed);
    g_progress = g3d_progress_term_init(&g_term, stderr, c->quiet);
}

g3d_progress g3d_cli_progress(void) { return g_progress; }

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    if (g_stop) _exit(G3D_EXIT_CANCELLED);
    g_stop = 1;
}

static int stop_requested(void *user)
{
    (void)user;
    return g_stop != 0;
}

g3d_cancel g3d_cli_cancel(void)
{
    static int installed;
    if (!installed) {
        struct sigaction sa;
        memset(&sa, 0, sizeof sa);
        sa.sa_handler = on_signal;
        sigemptyset(&sa.sa_mask);
        sigaction(SIGINT, &sa, NULL);
        sigaction(SIGTERM, &sa, NULL);
        installed = 1;
    }
    return (g3d_cancel){stop_requested, NULL};
}

static char *g_capture;
static size_t g_capture_n;

void g3d_cli_capture_errors(char *buf, size_t n)
{
    g_capture = buf;
    g_capture_n = n;
    if (buf && n) buf[0] = 0;
}

int g3d_cli_errorf(int code, const char *fmt, ...)
{
    va_list ap;
    if (g_capture) {
        if (!g_capture[0] && g_capture_n) {
            va_start(ap, fmt);
            vsnprintf(g_capture, g_capture_n, fmt, ap);
            va_end(ap);
        }
        return code;
    }
    fprintf(stderr, "gen3d: error: ");
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    return code;
}

int g3d_cli_fail(g3d_status rc)
{
    if (rc == G3D_CANCELLED) {
        fprintf(stderr, "gen3d: interrupted\n");
        return G3D_EXIT_CANCELLED;
    }
    const char *m = g3d_error_message();
    return g3d_cli_errorf(G3D_EXIT_FAIL, "%s", m && *m ? m : g3d_status_name(rc));
}

static void print_default(const g3d_opt *o, char *buf, size_t n)
{
    buf[0] = 0;
    /* help text that states its own default (or what 0 means) knows better than the raw value */
    if (o->help && (strstr(o->help, "(default") || strstr(o->help, "(0:"))) return;
    switch (o->kind) {
    case G3D_OPT_FLAG: break;
    case G3D_OPT_INT: snprintf(buf, n, " (default %d)", *(int *)o->target); break;
    case G3D_OPT_INT64: snprintf(buf, n, " (default %" PRId64 ")", *(int64_t *)o->target); break;
    case G3D_OPT_DOUBLE: snprintf(buf, n, " (default %g)", *(double *)o->target); break;
    case G3D_OPT_STRING:
    case G3D_OPT_PATH:
    case G3D_OPT_TRAJECTORY: {
        const char *s = *(const char **)o->target;
        if (s) snprintf(buf, n, " (default %s)", s);
        break;
    }
    }
}

static void print_help(const g3d_opt *opts, int nopts, const char *usage, const char *description)
{
    printf("usage: %s\n\n", usage);
    if (description && *description) printf("%s\n\n", description);
    printf("options:\n");
    for (int i = 0; i < nopts; i++) {
        const g3d_opt *o = &opts[i];
        char left[64], def[160];
        int k = 0;
        if (o->short_name) k += snprintf(left + k, sizeof left - k, "-%c, ", o->short_name);
        else k += snprintf(left + k, sizeof left - k, "    ");
        k += snprintf(left + k, sizeof left - k, "--%s", o->long_name);
        if (o->kind != G3D_OPT_FLAG && k < (int)sizeof left)
            snprintf(left + k, sizeof left - k, " %s", o->metavar ? o->metavar : "X");
        print_default(o, def, sizeof def);
        printf("  %-28s %s%s\n", left, o->help, def);
    }
    printf("  %-28s %s\n", "-h, --help", "show this help");
}

static int set_value(const g3d_opt *o, const char *name, const char *val)
{
    char *end;
    errno = 0;
    switch (o->kind) {
    case G3D_OPT_FLAG: *(int *)o->target = 1; return 0;
    case G3D_OPT_STRING:
    case G3D_OPT_PATH:
    case G3D_OPT_TRAJECTORY: *(const char **)o->target = val; return 0;
    case G3D_OPT_INT: {
        long v = strtol(val, &end, 10);
        if (errno || *end || end == val || v < -2147483647L || v > 2147483647L) break;
        *(int *)o->target = (int)v;
        return 0;
    }
    case G3D_OPT_INT64: {
        long long v = strtoll(val, &end, 10);
        if (errno || *end || end == val) break;
        *(int64_t *)o->target = (int64_t)v;
        return 0;
    }
    case G3D_OPT_DOUBLE: {
        double v = strtod(val, &end);
        if (errno || *end || end == val || !isfinite(v)) break;
        *(double *)o->target = v;
        return 0;
    }
    }
    return g3d_cli_errorf(G3D_EXIT_USAGE, "option %s: '%s' is not a valid %s", name, val,
                          o->kind == G3D_OPT_DOUBLE ? "number" : "integer");
}

int g3d_cli_parse(int argc, char **argv, const g3d_opt *opts, int nopts, const char *usage,
                  const char *description, const char **pos, int max_pos, int *npos)
{
    int only_pos = 0;
    *npos = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const g3d_opt *o = NULL;
        const char *val = NULL;
        char name[96];

        if (only_pos || a[0] != '-' || a[1] == 0 || (a[1] >= '0' && a[1] <= '9')) {
            if (*npos >= max_pos) return g3d_cli_errorf(G3D_EXIT_USAGE, "unexpected argument '%s' (see --help)", a);
            pos[(*npos)++] = a;
            continue;
        }
        if (!strcmp(a, "--")) { only_pos = 1; continue; }
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            print_help(opts, nopts, usage, description);
            return -1;
        }
        if (a[1] == '-') {
            const char *eq = strchr(a + 2, '=');
            size_t len = eq ? (size_t)(eq - (a + 2)) : strlen(a + 2);
            for (int k = 0; k < nopts; k++)
                if (strlen(opts[k].long_name) == len && !strncmp(opts[k].long_name, a + 2, len)) o = &opts[k];
            snprintf(name, sizeof name, "--%.*s", (int)len, a + 2);
            if (eq) val = eq + 1;
        } else {
            if (a[2] != 0) {
                /* -o/path style is not supported, to keep negative numbers unambiguous. */
                return g3d_cli_errorf(G3D_EXIT_USAGE, "unknown option '%s' (see --help)", a);
            }
            for (int k = 0; k < nopts; k++)
                if (opts[k].short_name == a[1]) o = &opts[k];
            snprintf(name, sizeof name, "-%c", a[1]);
        }
        if (!o) return g3d_cli_errorf(G3D_EXIT_USAGE, "unknown option '%s' (see --help)", a);
        if (o->kind == G3D_OPT_FLAG) {
            if (val) return g3d_cli_errorf(G3D_EXIT_USAGE, "option %s takes no value", name);
        } else if (!val) {
            if (i + 1 >= argc) return g3d_cli_errorf(G3D_EXIT_USAGE, "option %s needs a value", name);
            val = argv[++i];
        }
        int rc = set_value(o, name, val);
        if (rc) return rc;
    }
    return G3D_EXIT_OK;
}

int g3d_cli_set_option(const g3d_opt *opts, int nopts, const char *name, const char *value)
{
    char dashed[96];
    snprintf(dashed, sizeof dashed, "--%s", name);
    for (int k = 0; k < nopts; k++) {
        if (strcmp(opts[k].long_name, name)) continue;
        if (opts[k].kind == G3D_OPT_FLAG) {
            *(int *)opts[k].target = strcmp(value, "0") != 0;
            return G3D_EXIT_OK;
        }
        return set_value(&opts[k], dashed, value);
    }
    return g3d_cli_errorf(G3D_EXIT_USAGE, "unknown option '%s'", dashed);
}
