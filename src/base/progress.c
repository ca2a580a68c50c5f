/* Progress reporting: the callback plumbing and the terminal reporter used by the CLI. */
#include "gen3d/base.h"

#include <string.h>
#include <time.h>
#include <unistd.h>

double g3d_time_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int g3d_progress_report(const g3d_progress *p, const char *stage, int64_t step, int64_t total,
                        const char *info)
{
    if (!p || !p->fn) return 0;
    return p->fn(p->user, stage, step, total, info);
}

int g3d_cancel_requested(const g3d_cancel *c)
{
    return c && c->fn && c->fn(c->user) != 0;
}

static void fmt_duration(char *buf, size_t n, double s)
{
    if (s < 0 || s > 1e7) { snprintf(buf, n, "--"); return; }
    int t = (int)(s + 0.5);
    if (t >= 3600) snprintf(buf, n, "%dh%02dm", t / 3600, (t / 60) % 60);
    else if (t >= 60) snprintf(buf, n, "%dm%02ds", t / 60, t % 60);
    else snprintf(buf, n, "%ds", t);
}

static int term_report(void *user, const char *stage, int64_t step, int64_t total, const char *info)
{
    g3d_progress_term *st = user;
    double now = g3d_time_now();
    int new_stage = strncmp(st->stage, stage, sizeof st->stage - 1) != 0;
    int done = total > 0 && step >= total;
    char eta[32] = "", line[256];
    double rate;

    if (st->quiet || !st->is_tty) return 0;
    if (new_stage) {
        if (st->stage[0]) fputc('\n', st->out);
        snprintf(st->stage, sizeof st->stage, "%s", stage);
        st->t_stage = now;
        st->t_last = 0;
        st->first_step = step;
    }
    /* Redraw at most ~10 times a second. */
    if (!done && now - st->t_last < 0.1) return 0;
    st->t_last = now;

    rate = now > st->t_stage && step > st->first_step ? (double)(step - st->first_step) / (now - st->t_stage) : 0.0;
    char speed[32] = "";
    if (rate > 0) snprintf(speed, sizeof speed, "  %.1f/s", rate);
    if (total > 0 && rate > 0 && !done) fmt_duration(eta, sizeof eta, (double)(total - step) / rate);
    if (total > 0)
        snprintf(line, sizeof line, "%-10s %lld/%lld%s%s%s%s%s", stage, (long long)step, (long long)total, speed,
                 eta[0] ? "  ETA " : "", eta, info ? "  " : "", info ? info : "");
    else
        snprintf(line, sizeof line, "%-10s %lld%s%s", stage, (long long)step, info ? "  " : "", info ? info : "");

    fprintf(st->out, "\r\033[K%s", line);
    if (done) { fputc('\n', st->out); st->stage[0] = 0; }
    fflush(st->out);
    return 0;
}

g3d_progress g3d_progress_term_init(g3d_progress_term *state, FILE *out, int quiet)
{
    g3d_progress p;
    memset(state, 0, sizeof *state);
    state->out = out;
    state->quiet = quiet;
    state->is_tty = isatty(fileno(out));
    p.fn = term_report;
    p.user = state;
    return p;
}
