/* The Slurm job-array script: task K of the array runs shard K of the manifest. */
#include "gen3d/batch.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct text {
    char *s;
    size_t n, cap;
    int failed;
} text;

static void addf(text *t, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static void addf(text *t, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (t->failed || k < 0) {
        t->failed = 1;
        return;
    }
    if (t->n + (size_t)k + 1 > t->cap) {
        size_t cap = (t->n + (size_t)k + 1) * 2;
        char *s = realloc(t->s, cap);
        if (!s) {
            t->failed = 1;
            return;
        }
        t->s = s;
        t->cap = cap;
    }
    va_start(ap, fmt);
    vsnprintf(t->s + t->n, t->cap - t->n, fmt, ap);
    va_end(ap);
    t->n += (size_t)k;
}

/* One word for sh: single-quoted, a quote inside written as '\''. */
static void add_quoted(text *t, const char *w)
{
    addf(t, " '");
    for (const char *c = w; *c; c++) {
        if (*c == '\'') addf(t, "'\\''");
        else addf(t, "%c", *c);
    }
    addf(t, "'");
}

/* #SBATCH lines are read by sbatch, not by a shell: a value may not hold a line break. */
static int one_line(const char *s) { return !s || !strpbrk(s, "\n\r"); }

g3d_status g3d_batch_slurm_script(const g3d_batch_slurm *s, char **out)
{
    *out = NULL;
    if (!s->exe || !s->manifest || !s->output || s->cpus_per_task < 1 || s->shards < 1 || s->ntasks < 1)
        return G3D_ERR(G3D_ERR_ARG, "slurm script: program, manifest, output, CPUs, shards and tasks are needed");
    int ok = one_line(s->job_name) && one_line(s->partition) && one_line(s->time) && one_line(s->gres);
    for (int i = 0; i < s->nsbatch_args; i++) ok = ok && one_line(s->sbatch_args[i]);
    for (int i = 0; i < s->ntasks; i++) ok = ok && s->tasks[i] >= 0 && s->tasks[i] < s->shards;
    if (!ok) return G3D_ERR(G3D_ERR_ARG, "slurm script: a setting holds a line break, or a task is not a shard");
    text t = {0};
    addf(&t, "#!/bin/sh\n");
    addf(&t, "# gen3d batch as a Slurm job array: array task K runs the scenes of shard K/%d of the\n", s->shards);
    addf(&t, "# manifest (scene i belongs to shard i mod %d). Written by gen3d batch --slurm; submit it\n", s->shards);
    addf(&t, "# again to run what is still missing (finished scenes are skipped).\n");
    addf(&t, "#SBATCH --job-name=%s\n", s->job_name ? s->job_name : "gen3d-batch");
    addf(&t, "#SBATCH --array=");
    /* runs of consecutive shards as ranges, e.g. 0-3,7 */
    for (int i = 0; i < s->ntasks;) {
        int j = i;
        while (j + 1 < s->ntasks && s->tasks[j + 1] == s->tasks[j] + 1) j++;
        addf(&t, "%s%d", i ? "," : "", s->tasks[i]);
        if (j > i) addf(&t, "-%d", s->tasks[j]);
        i = j + 1;
    }
    addf(&t, "\n#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=%d\n", s->cpus_per_task);
    addf(&t, "#SBATCH --output=%s/slurm/%%A_%%a.out\n", s->output);
    if (s->partition) addf(&t, "#SBATCH --partition=%s\n", s->partition);
    if (s->time) addf(&t, "#SBATCH --time=%s\n", s->time);
    if (s->gres) addf(&t, "#SBATCH --gres=%s\n", s->gres);
    for (int i = 0; i < s->nsbatch_args; i++) addf(&t, "#SBATCH %s\n", s->sbatch_args[i]);
    addf(&t, "set -u\nexec");
    add_quoted(&t, s->exe);
    addf(&t, " batch");
    add_quoted(&t, s->manifest);
    if (s->defaults) {
        addf(&t, " --defaults");
        add_quoted(&t, s->defaults);
    }
    addf(&t, " -o");
    add_quoted(&t, s->output);
    addf(&t, " --shard \"$SLURM_ARRAY_TASK_ID/%d\" --jobs 1 -t \"${SLURM_CPUS_PER_TASK:-%d}\"", s->shards, s->cpus_per_task);
    for (int i = 0; i < s->nbatch_args; i++) add_quoted(&t, s->batch_args[i]);
    addf(&t, "\n");
    if (t.failed) {
        free(t.s);
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    *out = t.s;
    return G3D_OK;
}
