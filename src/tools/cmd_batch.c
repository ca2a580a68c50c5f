/* gen3d batch: many scenes from a JSON Lines manifest, on this machine or as a Slurm job array.
 *
 * Each scene runs in a child process of its own (fork): a scene that crashes or runs out of
 * memory fails alone, and --jobs N scenes run side by side with their own OpenMP thread pools
 * (cores / N threads each). The parent never runs OpenMP work itself, so every child starts
 * from a fresh runtime. */
#include "generate_opts.h"

#include "gen3d/batch.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <omp.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

enum { CHILD_DONE = 0, CHILD_FAILED = 1, CHILD_BUSY = 3 };
#define MAX_LIST 10   /* failed scenes and bad lines shown in the summary */

typedef struct batch_opts {
    const char *manifest, *defaults, *output, *shard, *status_dir;
    const char *partition, *time, *gres, *job_name;
    int check, jobs, retry_failed, force, dry_run, slurm, cpus_per_task, array_size;
    int threads, quiet, verbose;
    const char **sbatch_args;
    int nsbatch_args;
} batch_opts;

/* ---- manifest keys: generate's options -------------------------------------------------------- */

/* Options that belong to the batch, not to a scene. */
static int batch_only(const char *name)
{
    return !strcmp(name, "output") || !strcmp(name, "threads") || !strcmp(name, "quiet") || !strcmp(name, "verbose");
}

static int manifest_keys(g3d_batch_key *keys)
{
    g3d_cli_generate g;
    g3d_opt opts[G3D_GENERATE_MAX_OPTS];
    g3d_cli_generate_init(&g);
    int n = g3d_cli_generate_opts(&g, opts), k = 0;
    for (int i = 0; i < n; i++) {
        if (batch_only(opts[i].long_name)) continue;
        g3d_batch_key *key = &keys[k++];
        key->name = opts[i].long_name;
        key->names = NULL;
        switch (opts[i].kind) {
        case G3D_OPT_FLAG: key->kind = G3D_BATCH_FLAG; break;
        case G3D_OPT_INT:
        case G3D_OPT_INT64: key->kind = G3D_BATCH_INT; break;
        case G3D_OPT_DOUBLE: key->kind = G3D_BATCH_NUMBER; break;
        case G3D_OPT_STRING: key->kind = G3D_BATCH_STRING; break;
        case G3D_OPT_PATH: key->kind = G3D_BATCH_PATH; break;
        case G3D_OPT_TRAJECTORY:
            key->kind = G3D_BATCH_NAME_OR_PATH;
            key->names = g3d_trajectory_names();
            break;
        }
    }
    return k;
}

/* Fills g from a scene's options and checks them as `gen3d generate` would. Returns 0, or
 * non-zero with the problem in msg. */
static int scene_options(const g3d_batch_scene *s, g3d_cli_generate *g, char *msg, size_t n)
{
    g3d_opt opts[G3D_GENERATE_MAX_OPTS];
    g3d_cli_generate_init(g);
    int nopts = g3d_cli_generate_opts(g, opts), rc = 0;
    g3d_cli_capture_errors(msg, n);
    for (int i = 0; i < s->nopts && !rc; i++) rc = g3d_cli_set_option(opts, nopts, s->opts[i].key, s->opts[i].value);
    if (!rc) rc = g3d_cli_generate_check(g);
    if (!rc && g->common.seed < 0) rc = g3d_cli_errorf(G3D_EXIT_USAGE, "seed must be >= 0 (a batch is repeatable)");
    g3d_cli_capture_errors(NULL, 0);
    return rc;
}

static void check_values(g3d_batch_manifest *m)
{
    for (int i = 0; i < m->nscenes; i++) {
        g3d_batch_scene *s = &m->scenes[i];
        g3d_cli_generate g;
        char msg[512];
        if (!s->error && scene_options(s, &g, msg, sizeof msg)) g3d_batch_scene_set_error(s, msg);
    }
}

static void report_line(const g3d_batch_manifest *m, const g3d_batch_scene *s)
{
    if (s->id) fprintf(stderr, "gen3d: error: %s:%d: scene '%s': %s\n", m->path, s->line, s->id, s->error);
    else fprintf(stderr, "gen3d: error: %s:%d: %s\n", m->path, s->line, s->error);
}

/* ---- one scene, in a child process ------------------------------------------------------------ */

static char *scene_path(const char *dir, const char *id, const char *suffix)
{
    size_t n = strlen(dir) + strlen(id) + strlen(suffix) + 16;
    char *p = malloc(n);
    if (p) snprintf(p, n, "%s/.batch/work/%s%s", dir, id, suffix);
    return p;
}

/* Builds the scene in its work folder and moves it into place; returns the child's exit code. */
static int run_scene(const batch_opts *o, const g3d_batch_scene *s, int threads)
{
    int lock;
    if (g3d_batch_lock(o->output, s->id, &lock) != G3D_OK) return g3d_cli_fail(G3D_ERR_IO);
    if (lock < 0) return CHILD_BUSY;
    char *work = g3d_batch_work_dir(o->output, s->id), *log = scene_path(o->output, s->id, ".log");
    if (!work || !log) return g3d_cli_fail(G3D_ERR_NOMEM);
    /* the scene's messages go to its log, which ends up in its folder */
    int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd >= 0) {
        fflush(stderr);
        dup2(fd, 2);
        close(fd);
    }
    g3d_log_set_level(o->verbose ? G3D_LOG_DEBUG : G3D_LOG_INFO);
    omp_set_num_threads(threads);
    double t0 = g3d_time_now();
    char msg[1024] = "";
    g3d_generate_result r;
    memset(&r, 0, sizeof r);
    g3d_status rc = G3D_OK;
    if (s->error) {
        snprintf(msg, sizeof msg, "%s", s->error);
    } else {
        g3d_cli_generate g;
        scene_options(s, &g, msg, sizeof msg);   /* checked before the fork: cannot fail here */
        g3d_cli_generate_apply(&g);
        g.p.output_dir = work;
        g.p.cancel = g3d_cli_cancel();
        g3d_log(G3D_LOG_INFO, "scene %s (manifest line %d), %d threads", s->id, s->line, threads);
        rc = g3d_generate(&g.p, &r);
        if (rc == G3D_CANCELLED) {
            remove(log);
            return G3D_EXIT_CANCELLED;
        }
        if (rc != G3D_OK) snprintf(msg, sizeof msg, "%s", g3d_error_message());
    }
    if (msg[0]) {
        g3d_log(G3D_LOG_ERROR, "%s", msg);
        g3d_remove_tree(work);
        rc = g3d_mkdirs(work);
    }
    if (rc == G3D_OK) rc = g3d_batch_status_write(work, s, msg[0] ? msg : NULL, msg[0] ? NULL : r.seconds, g3d_time_now() - t0, threads);
    g3d_generate_result_free(&r);
    char *log_in = g3d_path_join(work, "log.txt");
    if (rc == G3D_OK && log_in && rename(log, log_in) != 0) remove(log);
    free(log_in);
    if (rc == G3D_OK) rc = g3d_batch_commit(o->output, s->id, work);
    if (rc != G3D_OK) {
        g3d_remove_tree(work);
        return g3d_cli_fail(rc);
    }
    g3d_batch_unlock(lock);
    free(work);
    free(log);
    return msg[0] ? CHILD_FAILED : CHILD_DONE;
}

/* A child that died without a status file (a crash, the OOM killer) gets one from here. */
static void record_crash(const batch_opts *o, const g3d_batch_scene *s, int sig, double seconds, int threads)
{
    int lock;
    if (g3d_batch_lock(o->output, s->id, &lock) != G3D_OK || lock < 0) return;
    char *work = g3d_batch_work_dir(o->output, s->id), *log = scene_path(o->output, s->id, ".log");
    char *log_in = work ? g3d_path_join(work, "log.txt") : NULL;
    char msg[128];
    snprintf(msg, sizeof msg, "the process running the scene was killed by signal %d (%s)", sig, strsignal(sig));
    if (log_in && g3d_mkdirs(work) == G3D_OK && g3d_batch_status_write(work, s, msg, NULL, seconds, threads) == G3D_OK) {
        if (rename(log, log_in) != 0) remove(log);
        if (g3d_batch_commit(o->output, s->id, work) != G3D_OK) g3d_remove_tree(work);
    }
    free(log_in);
    free(log);
    free(work);
    g3d_batch_unlock(lock);
}

/* ---- choosing and running scenes -------------------------------------------------------------- */

/* 1 when the scene (which has an id) should run now. */
static int wanted(const batch_opts *o, g3d_batch_state st)
{
    switch (st) {
    case G3D_BATCH_PENDING: return 1;
    case G3D_BATCH_RUNNING: return 0;
    case G3D_BATCH_FAILED: return o->retry_failed || o->force;
    case G3D_BATCH_DONE: return o->force;
    }
    return 0;
}

static void format_duration(char *buf, size_t n, double s)
{
    if (s < 90) snprintf(buf, n, "%.0f s", s);
    else if (s < 5400) snprintf(buf, n, "%d min %02d s", (int)(s / 60), (int)s % 60);
    else snprintf(buf, n, "%d h %02d min", (int)(s / 3600), (int)(s / 60) % 60);
}

typedef struct slot {
    pid_t pid;
    int scene;
    double t0;
} slot;

typedef struct run_counts {
    int ran, done, failed, busy, cancelled;
} run_counts;

/* Runs the scenes listed in todo, `jobs` at a time; returns 1 when stopped by a signal. */
static int run_all(const batch_opts *o, const g3d_batch_manifest *m, const int *todo, int ntodo, int threads,
                   run_counts *c)
{
    slot *slots = calloc((size_t)o->jobs, sizeof *slots);
    g3d_cancel cancel = g3d_cli_cancel();
    double done_secs = 0;
    int ndone = 0, next = 0, active = 0, finished = 0, forwarded = 0;
    if (!slots) return g3d_cli_fail(G3D_ERR_NOMEM), 1;
    while (next < ntodo || active > 0) {
        while (active < o->jobs && next < ntodo && !g3d_cancel_requested(&cancel)) {
            int j = 0;
            while (slots[j].pid) j++;
            fflush(NULL);
            pid_t pid = fork();
            if (pid == 0) _exit(run_scene(o, &m->scenes[todo[next]], threads));
            if (pid < 0) {
                g3d_cli_errorf(G3D_EXIT_FAIL, "cannot start a process (%s)", strerror(errno));
                c->cancelled = 1;
                break;
            }
            slots[j] = (slot){pid, todo[next], g3d_time_now()};
            active++;
            next++;
        }
        if (active == 0) break;
        int status;
        pid_t pid = waitpid(-1, &status, 0);
        if (pid < 0 && errno == EINTR && g3d_cancel_requested(&cancel) && !forwarded) {
            /* a stop asked of this process (Ctrl-C reaches the whole group anyway; scancel
             * or kill may not) goes on to the scenes, which clean up and exit */
            for (int j = 0; j < o->jobs; j++)
                if (slots[j].pid) kill(slots[j].pid, SIGTERM);
            forwarded = 1;
        }
        if (pid < 0) {
            if (errno == EINTR) continue;
            break;
        }
        int j = 0;
        while (j < o->jobs && slots[j].pid != pid) j++;
        if (j == o->jobs) continue;
        const g3d_batch_scene *s = &m->scenes[slots[j].scene];
        double secs = g3d_time_now() - slots[j].t0;
        slots[j].pid = 0;
        active--;
        int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        if (WIFSIGNALED(status)) record_crash(o, s, WTERMSIG(status), secs, threads);
        if (code == CHILD_BUSY) {
            c->busy++;
            continue;
        }
        if (code == G3D_EXIT_CANCELLED) {
            c->cancelled = 1;
            continue;
        }
        c->ran++;
        finished++;
        g3d_batch_status st;
        g3d_batch_state state = g3d_batch_scene_state(o->output, s->id, &st);
        if (state == G3D_BATCH_DONE && code == CHILD_DONE) c->done++;
        else c->failed++;
        if (state != G3D_BATCH_DONE || code != CHILD_DONE)
            fprintf(stderr, "gen3d: error: scene '%s' (%s:%d): %s\n", s->id, m->path, s->line,
                    st.error ? st.error : code == CHILD_FAILED ? "failed" : "could not record its result");
        if (!o->quiet) {
            char took[32], eta[48] = "";
            format_duration(took, sizeof took, secs);
            int left = ntodo - next + active;
            if (state == G3D_BATCH_DONE) {
                done_secs += secs;
                ndone++;
            }
            /* from the scenes that ran through: one failing at once says nothing of the rest */
            if (left > 0 && ndone > 0 && !g3d_cancel_requested(&cancel)) {
                char d[32];
                format_duration(d, sizeof d, done_secs / ndone * ((left + o->jobs - 1) / o->jobs));
                snprintf(eta, sizeof eta, ", ETA %s", d);
            }
            fprintf(stderr, "[%d/%d] %-6s %s (%s)%s\n", finished, ntodo, state == G3D_BATCH_DONE ? "done" : "failed",
                    s->id, took, eta);
        }
        g3d_batch_status_free(&st);
    }
    free(slots);
    return c->cancelled || g3d_cancel_requested(&cancel);
}

/* ---- summary and status ----------------------------------------------------------------------- */

/* The state of every scene now (bad lines without an id: pending); errors[i] owned. */
static void read_states(const char *dir, const g3d_batch_manifest *m, g3d_batch_state *states, char **errors)
{
    for (int i = 0; i < m->nscenes; i++) {
        g3d_batch_status st;
        states[i] = G3D_BATCH_PENDING;
        errors[i] = NULL;
        if (!m->scenes[i].id) continue;
        states[i] = g3d_batch_scene_state(dir, m->scenes[i].id, &st);
        errors[i] = st.error;
        st.error = NULL;
        g3d_batch_status_free(&st);
    }
}

static void print_counts(const char *dir, const g3d_batch_manifest *m, const g3d_batch_state *states)
{
    int count[4] = {0, 0, 0, 0}, bad = 0;
    for (int i = 0; i < m->nscenes; i++) {
        if (m->scenes[i].id) count[states[i]]++;
        else bad++;
    }
    printf("%s: %d scenes: %d done, %d failed, %d running, %d pending", dir, m->nscenes - bad, count[G3D_BATCH_DONE],
           count[G3D_BATCH_FAILED], count[G3D_BATCH_RUNNING], count[G3D_BATCH_PENDING]);
    if (bad) printf("; %d bad line%s without a scene", bad, bad > 1 ? "s" : "");
    printf("\n");
}

static int status_mode(const batch_opts *o, const g3d_batch_key *keys, int nkeys)
{
    char *manifest, *defaults;
    g3d_batch_manifest m;
    g3d_status rc = g3d_batch_folder_manifest(o->status_dir, &manifest, &defaults);
    if (rc == G3D_OK) rc = g3d_batch_manifest_load(manifest, defaults, keys, nkeys, &m);
    if (rc != G3D_OK) {
        free(manifest);
        free(defaults);
        return g3d_cli_fail(rc);
    }
    g3d_batch_state *states = calloc((size_t)m.nscenes, sizeof *states);
    char **errors = calloc((size_t)m.nscenes, sizeof *errors);
    if (!states || !errors) return g3d_cli_fail(G3D_ERR_NOMEM);
    read_states(o->status_dir, &m, states, errors);
    for (int i = 0; i < m.nscenes; i++) {
        const g3d_batch_scene *s = &m.scenes[i];
        if (!s->id) {
            printf("%-24s %-8s line %d: %s\n", "-", "bad", s->line, s->error);
            continue;
        }
        printf("%-24s %-8s", s->id, g3d_batch_state_name(states[i]));
        g3d_batch_status st;
        if (states[i] == G3D_BATCH_DONE && g3d_batch_scene_state(o->status_dir, s->id, &st) == G3D_BATCH_DONE) {
            char d[32];
            format_duration(d, sizeof d, st.seconds_total);
            printf(" %s", d);
            g3d_batch_status_free(&st);
        }
        if (states[i] == G3D_BATCH_FAILED && errors[i]) printf(" %s", errors[i]);
        printf("\n");
    }
    print_counts(o->status_dir, &m, states);
    for (int i = 0; i < m.nscenes; i++) free(errors[i]);
    free(errors);
    free(states);
    g3d_batch_manifest_free(&m);
    free(manifest);
    free(defaults);
    return G3D_EXIT_OK;
}

/* Writes summary.json and prints the one-screen summary; returns the number of failed scenes
 * among those of this shard. */
static int summarize(const batch_opts *o, const g3d_batch_manifest *m, int k, int n, const run_counts *c, int skipped,
                     double seconds)
{
    g3d_batch_state *states = calloc((size_t)m->nscenes, sizeof *states);
    char **errors = calloc((size_t)m->nscenes, sizeof *errors);
    if (!states || !errors) {
        free(states);
        free(errors);
        return g3d_cli_fail(G3D_ERR_NOMEM), 1;
    }
    read_states(o->output, m, states, errors);
    g3d_status rc = g3d_batch_summary_write(o->output, m, states, errors, seconds);
    if (rc != G3D_OK) g3d_cli_fail(rc);
    char took[32];
    format_duration(took, sizeof took, seconds);
    print_counts(o->output, m, states);
    printf("  this run%s: %d ran (%d done, %d failed), %d skipped (finished or running elsewhere), %s\n",
           n > 1 ? " (shard)" : "", c->ran, c->done, c->failed, skipped + c->busy, took);
    int failed = 0, shown = 0;
    for (int i = 0; i < m->nscenes; i++) {
        const g3d_batch_scene *s = &m->scenes[i];
        if (!g3d_batch_in_shard(s->index, k, n) || (s->id && states[i] != G3D_BATCH_FAILED) || (!s->id && !s->error))
            continue;
        if (failed++ == 0) printf("  failed:\n");
        if (shown++ < MAX_LIST) {
            if (s->id) printf("    %-20s %s\n", s->id, errors[i] ? errors[i] : "failed");
            else printf("    line %-15d %s\n", s->line, s->error);
        }
    }
    if (shown > MAX_LIST) printf("    ... and %d more (summary.json lists them all)\n", shown - MAX_LIST);
    printf("  %s/summary.json\n", o->output);
    for (int i = 0; i < m->nscenes; i++) free(errors[i]);
    free(errors);
    free(states);
    return failed;
}

/* ---- Slurm ------------------------------------------------------------------------------------ */

/* Runs sbatch on the script; the job id goes into id. */
static int submit(const char *script, char *id, size_t n)
{
    int fds[2];
    posix_spawn_file_actions_t fa;
    pid_t pid;
    char *argv[] = {"sbatch", "--parsable", (char *)script, NULL};
    if (pipe(fds) != 0) return g3d_cli_errorf(G3D_EXIT_FAIL, "cannot run sbatch (%s)", strerror(errno));
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fds[1], 1);
    posix_spawn_file_actions_addclose(&fa, fds[0]);
    int err = posix_spawnp(&pid, "sbatch", &fa, NULL, argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    close(fds[1]);
    if (err) {
        close(fds[0]);
        return g3d_cli_errorf(G3D_EXIT_FAIL, "cannot run sbatch (%s): is Slurm installed here?", strerror(err));
    }
    size_t k = 0;
    ssize_t r;
    while (k + 1 < n && ((r = read(fds[0], id + k, n - 1 - k)) > 0 || (r < 0 && errno == EINTR))) k += r > 0 ? (size_t)r : 0;
    id[k] = 0;
    close(fds[0]);
    int status;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
    id[strcspn(id, ";\n")] = 0;   /* --parsable: "jobid[;cluster]" */
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || !id[0])
        return g3d_cli_errorf(G3D_EXIT_FAIL, "sbatch %s failed (its message is above)", script);
    return G3D_EXIT_OK;
}

static int slurm_mode(const batch_opts *o, const g3d_batch_manifest *m, const int *todo, int ntodo)
{
    char exe[PATH_MAX], out_abs[PATH_MAX];
    ssize_t k = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (k <= 0) return g3d_cli_errorf(G3D_EXIT_FAIL, "cannot find the gen3d program (/proc/self/exe)");
    exe[k] = 0;
    if (!realpath(o->output, out_abs)) return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: %s", o->output, strerror(errno));
    int shards = o->array_size > 0 ? o->array_size : ntodo < 1000 ? ntodo : 1000;
    int *tasks = calloc((size_t)shards, sizeof *tasks), ntasks = 0;
    char *used = calloc((size_t)shards, 1);
    if (!tasks || !used) return g3d_cli_fail(G3D_ERR_NOMEM);
    for (int i = 0; i < ntodo; i++) used[m->scenes[todo[i]].index % shards] = 1;
    for (int i = 0; i < shards; i++)
        if (used[i]) tasks[ntasks++] = i;
    /* what the tasks pass on: a retry or a forced rerun applies to them */
    const char *fwd[4];
    int nfwd = 0;
    if (o->retry_failed) fwd[nfwd++] = "--retry-failed";
    if (o->force) fwd[nfwd++] = "--force";
    if (o->verbose) fwd[nfwd++] = "--verbose";
    g3d_batch_slurm s = {exe, m->path, m->defaults, out_abs, o->job_name, o->partition, o->time, o->gres,
                         o->cpus_per_task, shards, tasks, ntasks, o->sbatch_args, o->nsbatch_args, fwd, nfwd};
    char *text = NULL, *dir = g3d_path_join(out_abs, "slurm"), *script = dir ? g3d_path_join(dir, "batch.sbatch") : NULL;
    g3d_status rc = script ? g3d_batch_slurm_script(&s, &text) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = g3d_mkdirs(dir);
    if (rc == G3D_OK) rc = g3d_write_file_atomic(script, text, strlen(text));
    int ret = rc == G3D_OK ? G3D_EXIT_OK : g3d_cli_fail(rc);
    if (ret == G3D_EXIT_OK && o->dry_run) {
        printf("%s\n", script);
        if (!o->quiet) fprintf(stderr, "%d scenes in %d array tasks (not submitted: --dry-run)\n", ntodo, ntasks);
    } else if (ret == G3D_EXIT_OK) {
        char id[128];
        ret = submit(script, id, sizeof id);
        if (ret == G3D_EXIT_OK) {
            printf("%s\n", id);
            if (!o->quiet)
                fprintf(stderr, "submitted job array %s: %d scenes in %d tasks (%s); follow with: gen3d batch --status %s\n", id,
                        ntodo, ntasks, script, out_abs);
        }
    }
    free(text);
    free(script);
    free(dir);
    free(used);
    free(tasks);
    return ret;
}

/* ---- the command ------------------------------------------------------------------------------ */

static const char *const g_description =
    "Runs many scenes through the whole pipeline (as `gen3d generate`), one per line of a JSON Lines\n"
    "manifest: {\"id\": \"room1\", \"input\": \"room1.png\", \"depth\": \"room1_depth.png\", \"iters\": 2000}.\n"
    "The keys are generate's long options (flags take true/false); paths are relative to the\n"
    "manifest's folder; --defaults FILE holds one JSON object of keys every line starts from.\n"
    "Each scene goes to DIR/<id>/ (its files, status.json and log.txt), moved there when it is\n"
    "finished; DIR/summary.json and a summary on stdout close the run. A failing scene does not\n"
    "stop the others; the exit status is 1 when any failed. Running the command again runs only\n"
    "what is missing (--retry-failed, --force: see below).\n"
    "  gen3d batch MANIFEST --check               validate every line, run nothing\n"
    "  gen3d batch MANIFEST -o DIR [--jobs N]     run here, N scenes at once\n"
    "  gen3d batch MANIFEST -o DIR --shard K/N    only the scenes i with i mod N = K (inside a Slurm\n"
    "                                             array task the shard comes from the task id)\n"
    "  gen3d batch MANIFEST -o DIR --slurm [...]  write DIR/slurm/batch.sbatch, submit it (job id on stdout)\n"
    "  gen3d batch --status DIR                   done / failed / running / pending per scene\n"
    "docs/batch.md has the format, a Slurm recipe and how to resume.";

/* Takes the repeatable --sbatch-arg out of argv (the option table keeps one value per option). */
static int take_sbatch_args(int *argc, char **argv, batch_opts *o)
{
    int k = 1;
    o->sbatch_args = calloc((size_t)*argc, sizeof *o->sbatch_args);
    if (!o->sbatch_args) return g3d_cli_fail(G3D_ERR_NOMEM);
    for (int i = 1; i < *argc; i++) {
        if (!strncmp(argv[i], "--sbatch-arg=", 13)) o->sbatch_args[o->nsbatch_args++] = argv[i] + 13;
        else if (!strcmp(argv[i], "--sbatch-arg")) {
            if (i + 1 >= *argc) return g3d_cli_errorf(G3D_EXIT_USAGE, "option --sbatch-arg needs a value");
            o->sbatch_args[o->nsbatch_args++] = argv[++i];
        } else argv[k++] = argv[i];
    }
    *argc = k;
    return G3D_EXIT_OK;
}

static int run_batch(batch_opts *o, const g3d_batch_key *keys, int nkeys)
{
    g3d_batch_manifest m;
    g3d_status rc = g3d_batch_manifest_load(o->manifest, o->defaults, keys, nkeys, &m);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    check_values(&m);
    int ret = G3D_EXIT_OK;
    if (o->check) {
        int bad = g3d_batch_manifest_bad(&m);
        for (int i = 0; i < m.nscenes; i++)
            if (m.scenes[i].error) report_line(&m, &m.scenes[i]);
        if (!bad) printf("%s: %d scenes, all valid\n", m.path, m.nscenes);
        else printf("%s: %d of %d lines bad\n", m.path, bad, m.nscenes);
        g3d_batch_manifest_free(&m);
        return bad ? G3D_EXIT_FAIL : G3D_EXIT_OK;
    }
    int k = 0, n = 1;
    if (o->shard) {
        if (g3d_batch_shard_parse(o->shard, &k, &n) != G3D_OK) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "%s", g3d_error_message());
    } else if (!o->slurm && g3d_batch_shard_from_env(&k, &n) < 0) {
        ret = g3d_cli_errorf(G3D_EXIT_USAGE, "SLURM_ARRAY_TASK_ID and the array's size disagree: give --shard K/N");
    }
    if (ret == G3D_EXIT_OK && (rc = g3d_batch_folder_claim(o->output, &m)) != G3D_OK) ret = g3d_cli_fail(rc);
    int *todo = ret == G3D_EXIT_OK ? calloc((size_t)m.nscenes, sizeof *todo) : NULL;
    if (ret == G3D_EXIT_OK && !todo) ret = g3d_cli_fail(G3D_ERR_NOMEM);
    if (ret != G3D_EXIT_OK) {
        g3d_batch_manifest_free(&m);
        return ret;
    }
    int ntodo = 0, skipped = 0, bad = 0;
    for (int i = 0; i < m.nscenes; i++) {
        const g3d_batch_scene *s = &m.scenes[i];
        if (!g3d_batch_in_shard(s->index, k, n) && !o->slurm) continue;
        if (!s->id) {
            if (!o->slurm) report_line(&m, s);
            bad++;
            continue;
        }
        if (wanted(o, g3d_batch_scene_state(o->output, s->id, NULL))) todo[ntodo++] = i;
        else skipped++;
    }
    if (o->slurm) {
        for (int i = 0; i < m.nscenes; i++)
            if (m.scenes[i].error) report_line(&m, &m.scenes[i]);
        if (ntodo == 0) {
            if (!o->quiet) fprintf(stderr, "%s: nothing to run (%d scenes finished or running)\n", o->output, skipped);
        } else {
            ret = slurm_mode(o, &m, todo, ntodo);
        }
    } else if (o->dry_run) {
        for (int i = 0; i < ntodo; i++) printf("%s\n", m.scenes[todo[i]].id);
        if (!o->quiet) fprintf(stderr, "%d scenes to run, %d skipped (finished or running)\n", ntodo, skipped);
        ret = bad ? G3D_EXIT_FAIL : G3D_EXIT_OK;
    } else {
        int cores = o->threads > 0 ? o->threads : omp_get_num_procs();
        int threads = cores / o->jobs > 0 ? cores / o->jobs : 1;
        if (!o->quiet)
            fprintf(stderr, "%s: %d scene(s) to run%s, %d at a time with %d thread(s) each; %d skipped (finished or running)\n",
                    m.path, ntodo, n > 1 ? " in this shard" : "", o->jobs, threads, skipped);
        double t0 = g3d_time_now();
        run_counts c = {0};
        int stopped = run_all(o, &m, todo, ntodo, threads, &c);
        int failed = summarize(o, &m, k, n, &c, skipped, g3d_time_now() - t0);
        if (stopped) {
            fprintf(stderr, "gen3d: interrupted (run the command again to go on)\n");
            ret = G3D_EXIT_CANCELLED;
        } else {
            ret = failed || bad ? G3D_EXIT_FAIL : G3D_EXIT_OK;
        }
    }
    free(todo);
    g3d_batch_manifest_free(&m);
    return ret;
}

static int run(int argc, char **argv)
{
    batch_opts o;
    memset(&o, 0, sizeof o);
    o.jobs = 1;
    o.cpus_per_task = 4;
    int prc = take_sbatch_args(&argc, argv, &o);
    const char *sbatch_help = NULL;   /* --help's line; the values were taken out above */
    g3d_opt opts[] = {
        {'o', "output", G3D_OPT_STRING, &o.output, "DIR", "output folder: one sub-folder per scene"},
        {0, "defaults", G3D_OPT_STRING, &o.defaults, "FILE", "JSON object of keys every scene starts from"},
        {0, "check", G3D_OPT_FLAG, &o.check, NULL, "validate the manifest (every line) and run nothing"},
        {'j', "jobs", G3D_OPT_INT, &o.jobs, "N", "scenes at once, each with threads / N threads"},
        {0, "shard", G3D_OPT_STRING, &o.shard, "K/N", "run only the scenes i with i mod N = K"},
        {0, "retry-failed", G3D_OPT_FLAG, &o.retry_failed, NULL, "run failed scenes again too"},
        {0, "force", G3D_OPT_FLAG, &o.force, NULL, "run every scene again, finished ones included"},
        {0, "dry-run", G3D_OPT_FLAG, &o.dry_run, NULL, "list the scenes that would run (with --slurm: write the script, do not submit)"},
        {0, "status", G3D_OPT_STRING, &o.status_dir, "DIR", "report each scene's state in a batch folder"},
        {0, "slurm", G3D_OPT_FLAG, &o.slurm, NULL, "submit the scenes as a Slurm job array"},
        {0, "partition", G3D_OPT_STRING, &o.partition, "P", "Slurm partition (default: the cluster's)"},
        {0, "time", G3D_OPT_STRING, &o.time, "T", "Slurm time limit per array task, e.g. 4:00:00 (default: the partition's)"},
        {0, "cpus-per-task", G3D_OPT_INT, &o.cpus_per_task, "C", "CPUs of each array task (its scenes' threads)"},
        {0, "gres", G3D_OPT_STRING, &o.gres, "G", "Slurm generic resources per task, e.g. gpu:1"},
        {0, "array-size", G3D_OPT_INT, &o.array_size, "N", "array tasks = shards (0: one per scene to run, at most 1000)"},
        {0, "sbatch-arg", G3D_OPT_STRING, &sbatch_help, "ARG", "one more #SBATCH line, e.g. --account=X (repeatable)"},
        {0, "job-name", G3D_OPT_STRING, &o.job_name, "NAME", "Slurm job name (default gen3d-batch)"},
        {'t', "threads", G3D_OPT_INT, &o.threads, "N", "threads in all (0: all cores), split between the --jobs"},
        {'q', "quiet", G3D_OPT_FLAG, &o.quiet, NULL, "no progress or info messages"},
        {'v', "verbose", G3D_OPT_FLAG, &o.verbose, NULL, "debug messages in the scenes' logs"},
    };
    const char *pos[1];
    int npos = 0;
    if (prc == G3D_EXIT_OK)
        prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                            "gen3d batch MANIFEST [-o DIR] [--check | --jobs N | --shard K/N | --slurm ...] | --status DIR",
                            g_description, pos, 1, &npos);
    int ret = prc < 0 ? G3D_EXIT_OK : prc;
    if (prc == G3D_EXIT_OK) {
        o.manifest = npos ? pos[0] : NULL;
        if (o.status_dir && (o.manifest || o.output)) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "--status DIR takes no manifest or -o");
        else if (!o.status_dir && !o.manifest) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "no manifest (see --help)");
        else if (!o.status_dir && !o.check && !o.output) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "-o DIR is needed (or --check)");
        else if (o.jobs < 1 || o.jobs > 1024) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "--jobs must be in 1..1024");
        else if (o.cpus_per_task < 1 || o.array_size < 0 || o.array_size > 1000000)
            ret = g3d_cli_errorf(G3D_EXIT_USAGE, "--cpus-per-task must be positive, --array-size in 0..1000000");
        else if (o.slurm && o.shard) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "--slurm makes the shards itself: no --shard");
        else if (o.threads < 0) ret = g3d_cli_errorf(G3D_EXIT_USAGE, "--threads must be >= 0");
    }
    if (prc == G3D_EXIT_OK && ret == G3D_EXIT_OK) {
        if (o.quiet) g3d_log_set_level(G3D_LOG_WARN);
        g3d_batch_key keys[G3D_GENERATE_MAX_OPTS];
        int nkeys = manifest_keys(keys);
        ret = o.status_dir ? status_mode(&o, keys, nkeys) : run_batch(&o, keys, nkeys);
    }
    free(o.sbatch_args);
    return ret;
}

const g3d_command g3d_cmd_batch = {"batch", "many scenes from a JSON Lines manifest, here or as a Slurm job array", run};
