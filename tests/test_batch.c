/* The batch library: manifests against a key table (defaults, paths, names, errors per line),
 * shards from --shard and from Slurm's variables, scene states and locks, the Slurm script. */
#include "gen3d/batch.h"
#include "testutil.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#define G3D_COUNTOF(a) ((int)(sizeof(a) / sizeof((a)[0])))

static const char *const g_presets[] = {"rotate", "orbit_left", NULL};
static const g3d_batch_key g_keys[] = {
    {"iters", G3D_BATCH_INT, NULL},   {"fov", G3D_BATCH_NUMBER, NULL},      {"no-video", G3D_BATCH_FLAG, NULL},
    {"input", G3D_BATCH_PATH, NULL},  {"trajectory", G3D_BATCH_NAME_OR_PATH, g_presets},
    {"video-trajectory", G3D_BATCH_STRING, NULL},
};

static void write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    if (f) {
        fputs(text, f);
        fclose(f);
    }
}

static const char *dir_with(const char *name)
{
    const char *d = test_tmp(name);
    g3d_remove_tree(d);
    g3d_mkdirs(d);
    return d;
}

TEST(manifest_values_defaults_and_paths)
{
    const char *d = dir_with("batch_manifest");
    char m[512], def[512], img[512], cams[512];
    snprintf(m, sizeof m, "%s/m.jsonl", d);
    snprintf(def, sizeof def, "%s/defaults.json", d);
    snprintf(img, sizeof img, "%s/a.png", d);
    snprintf(cams, sizeof cams, "%s/path.json", d);
    write_text(img, "x");
    write_text(cams, "[]");
    write_text(def, "{\"iters\": 50, \"no-video\": true, \"fov\": 40}");
    write_text(m, "{\"id\": \"one\", \"input\": \"a.png\", \"iters\": 7, \"trajectory\": \"rotate\"}\r\n"
                  "\n"
                  "  {\"id\": \"two\", \"no-video\": false, \"fov\": 55.25, \"trajectory\": \"path.json\", \"video-trajectory\": \"swing\"}\n");
    g3d_batch_manifest b;
    CHECK_OK(g3d_batch_manifest_load(m, def, g_keys, G3D_COUNTOF(g_keys), &b));
    CHECK(b.nscenes == 2);
    if (b.nscenes == 2) {
        const g3d_batch_scene *s = &b.scenes[0], *t = &b.scenes[1];
        CHECK(!s->error && !t->error);
        CHECK(s->index == 0 && s->line == 1 && t->index == 1 && t->line == 3);
        CHECK(!strcmp(s->id, "one") && !strcmp(t->id, "two"));
        CHECK(!strcmp(g3d_batch_scene_get(s, "iters"), "7"));          /* the line overrides */
        CHECK(!strcmp(g3d_batch_scene_get(t, "iters"), "50"));         /* the default */
        CHECK(!strcmp(g3d_batch_scene_get(s, "no-video"), "1"));
        CHECK(!strcmp(g3d_batch_scene_get(t, "no-video"), "0"));
        CHECK(strtod(g3d_batch_scene_get(t, "fov"), NULL) == 55.25);
        CHECK(!strcmp(g3d_batch_scene_get(s, "input"), img));         /* resolved, absolute */
        CHECK(!strcmp(g3d_batch_scene_get(s, "trajectory"), "rotate")); /* a name stays a name */
        CHECK(!strcmp(g3d_batch_scene_get(t, "trajectory"), cams));    /* anything else is a file */
        CHECK(!strcmp(g3d_batch_scene_get(t, "video-trajectory"), "swing"));
        CHECK(g3d_batch_scene_get(t, "input") == NULL);
        CHECK(g3d_batch_manifest_bad(&b) == 0);
    }
    CHECK(b.defaults && !strcmp(b.defaults, def));
    g3d_batch_manifest_free(&b);
}

/* The error of the scene on a given line, or "" */
static const char *error_on(const g3d_batch_manifest *b, int line)
{
    for (int i = 0; i < b->nscenes; i++)
        if (b->scenes[i].line == line) return b->scenes[i].error ? b->scenes[i].error : "";
    return "(no such line)";
}

TEST(manifest_errors_per_line)
{
    const char *d = dir_with("batch_bad");
    char m[512];
    snprintf(m, sizeof m, "%s/m.jsonl", d);
    write_text(m, "{\"id\": \"a\", \"iters\": 3}\n"          /* 1 good */
                  "{\"id\": \"b\", \"iters\": 3.5}\n"        /* 2 not whole */
                  "{\"id\": \"c\", \"colour\": 1}\n"         /* 3 unknown key */
                  "{\"id\": \"d\", \"input\": \"no.png\"}\n" /* 4 missing file */
                  "{\"id\": \"a\"}\n"                        /* 5 duplicate */
                  "[1, 2]\n"                                 /* 6 not an object */
                  "{\"id\": \"e\"} trailing\n"               /* 7 not JSON */
                  "{\"id\": \"x/y\"}\n"                      /* 8 bad id */
                  "{\"id\": \"f\", \"no-video\": 1}\n"       /* 9 flag needs a bool */
                  "{\"id\": \"g\", \"trajectory\": \"nowhere\"}\n"); /* 10 neither name nor file */
    g3d_batch_manifest b;
    CHECK_OK(g3d_batch_manifest_load(m, NULL, g_keys, G3D_COUNTOF(g_keys), &b));
    CHECK(b.nscenes == 10);
    CHECK(!strcmp(error_on(&b, 1), ""));
    CHECK(strstr(error_on(&b, 2), "iters: expected a whole number"));
    CHECK(strstr(error_on(&b, 3), "unknown key 'colour'"));
    CHECK(strstr(error_on(&b, 4), "input: no.png"));
    CHECK(strstr(error_on(&b, 5), "duplicate id 'a' (first on line 1)"));
    CHECK(strstr(error_on(&b, 6), "not a JSON object"));
    CHECK(strstr(error_on(&b, 7), "not JSON"));
    CHECK(strstr(error_on(&b, 8), "\"id\" must be"));
    CHECK(strstr(error_on(&b, 9), "no-video: expected true or false"));
    CHECK(strstr(error_on(&b, 10), "trajectory: nowhere"));
    CHECK(b.nscenes == 10 && b.scenes[4].id == NULL);   /* the duplicate has no folder of its own */
    CHECK(g3d_batch_manifest_bad(&b) == 9);
    g3d_batch_manifest_free(&b);

    /* files that cannot be used at all */
    char empty[512], def[512];
    snprintf(empty, sizeof empty, "%s/empty.jsonl", d);
    snprintf(def, sizeof def, "%s/def.json", d);
    write_text(empty, "\n  \n");
    CHECK(g3d_batch_manifest_load(empty, NULL, g_keys, G3D_COUNTOF(g_keys), &b) == G3D_ERR_FORMAT);
    write_text(def, "{\"iters\": \"many\"}");
    CHECK(g3d_batch_manifest_load(m, def, g_keys, G3D_COUNTOF(g_keys), &b) == G3D_ERR_FORMAT);
    CHECK(strstr(g3d_error_message(), "def.json"));
    CHECK(g3d_batch_manifest_load("/nonexistent/m.jsonl", NULL, g_keys, G3D_COUNTOF(g_keys), &b) == G3D_ERR_IO);
}

TEST(shards)
{
    int k, n;
    CHECK_OK(g3d_batch_shard_parse("2/5", &k, &n));
    CHECK(k == 2 && n == 5);
    const char *bad[] = {"5/5", "1", "/3", "a/3", "1/0", "-1/3", "1/3x", ""};
    for (int i = 0; i < G3D_COUNTOF(bad); i++) CHECK_MSG(g3d_batch_shard_parse(bad[i], &k, &n) == G3D_ERR_ARG, "%s", bad[i]);
    int hits[3] = {0, 0, 0};
    for (int i = 0; i < 30; i++)
        for (int s = 0; s < 3; s++) hits[s] += g3d_batch_in_shard(i, s, 3);
    CHECK(hits[0] == 10 && hits[1] == 10 && hits[2] == 10);
    CHECK(g3d_batch_in_shard(7, 0, 1));

    unsetenv("SLURM_ARRAY_TASK_ID");
    unsetenv("SLURM_ARRAY_TASK_MIN");
    unsetenv("SLURM_ARRAY_TASK_MAX");
    unsetenv("SLURM_ARRAY_TASK_COUNT");
    CHECK(g3d_batch_shard_from_env(&k, &n) == 0 && k == 0 && n == 1);
    setenv("SLURM_ARRAY_TASK_ID", "3", 1);
    setenv("SLURM_ARRAY_TASK_COUNT", "4", 1);
    CHECK(g3d_batch_shard_from_env(&k, &n) == 1 && k == 3 && n == 4);
    /* an array 10-13: counted from its first index */
    setenv("SLURM_ARRAY_TASK_ID", "12", 1);
    setenv("SLURM_ARRAY_TASK_MIN", "10", 1);
    unsetenv("SLURM_ARRAY_TASK_COUNT");
    setenv("SLURM_ARRAY_TASK_MAX", "13", 1);
    CHECK(g3d_batch_shard_from_env(&k, &n) == 1 && k == 2 && n == 4);
    setenv("SLURM_ARRAY_TASK_ID", "14", 1);
    CHECK(g3d_batch_shard_from_env(&k, &n) == -1);
    unsetenv("SLURM_ARRAY_TASK_ID");
    unsetenv("SLURM_ARRAY_TASK_MIN");
    unsetenv("SLURM_ARRAY_TASK_MAX");
}

TEST(folder_states_and_locks)
{
    const char *d = dir_with("batch_folder");
    char m[512], out[512], m2[512];
    snprintf(m, sizeof m, "%s/m.jsonl", d);
    snprintf(m2, sizeof m2, "%s/other.jsonl", d);
    snprintf(out, sizeof out, "%s/out", d);
    write_text(m, "{\"id\": \"a\", \"iters\": 5}\n{\"id\": \"b\"}\n");
    write_text(m2, "{\"id\": \"a\"}\n");
    g3d_batch_manifest b, b2;
    CHECK_OK(g3d_batch_manifest_load(m, NULL, g_keys, G3D_COUNTOF(g_keys), &b));
    CHECK_OK(g3d_batch_manifest_load(m2, NULL, g_keys, G3D_COUNTOF(g_keys), &b2));
    CHECK_OK(g3d_batch_folder_claim(out, &b));
    CHECK_OK(g3d_batch_folder_claim(out, &b));   /* again: the same manifest */
    CHECK(g3d_batch_folder_claim(out, &b2) == G3D_ERR_ARG);
    CHECK(strstr(g3d_error_message(), "another manifest"));
    char *fm, *fd;
    CHECK_OK(g3d_batch_folder_manifest(out, &fm, &fd));
    CHECK(fm && !strcmp(fm, b.path) && fd == NULL);
    free(fm);
    CHECK(g3d_batch_folder_claim(d, &b) == G3D_ERR_ARG);   /* a folder with other files */

    CHECK(g3d_batch_scene_state(out, "a", NULL) == G3D_BATCH_PENDING);
    int fd1, fd2;
    CHECK_OK(g3d_batch_lock(out, "a", &fd1));
    CHECK(fd1 >= 0);
    /* another process sees the lock: the scene is running, and cannot be taken */
    pid_t pid = fork();
    if (pid == 0) {
        int f;
        int busy = g3d_batch_lock(out, "a", &f) == G3D_OK && f < 0;
        _exit(busy && g3d_batch_scene_state(out, "a", NULL) == G3D_BATCH_RUNNING ? 0 : 1);
    }
    int status = -1;
    waitpid(pid, &status, 0);
    CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0);

    char *work = g3d_batch_work_dir(out, "a");
    CHECK(work != NULL);
    CHECK_OK(g3d_mkdirs(work));
    double secs[G3D_STAGE_COUNT] = {1, 2, 3, 4, 5};
    CHECK_OK(g3d_batch_status_write(work, &b.scenes[0], NULL, secs, 15, 3));
    CHECK_OK(g3d_batch_commit(out, "a", work));
    g3d_batch_unlock(fd1);
    g3d_batch_status st;
    CHECK(g3d_batch_scene_state(out, "a", &st) == G3D_BATCH_DONE);
    CHECK(st.seconds[G3D_STAGE_SPLATS] == 4 && st.seconds_total == 15 && st.error == NULL);
    g3d_batch_status_free(&st);

    /* a failed rerun replaces the earlier result whole */
    CHECK_OK(g3d_batch_lock(out, "a", &fd2));
    free(work);
    work = g3d_batch_work_dir(out, "a");
    CHECK_OK(g3d_mkdirs(work));
    CHECK_OK(g3d_batch_status_write(work, &b.scenes[0], "x.png: broken", NULL, 1, 1));
    CHECK_OK(g3d_batch_commit(out, "a", work));
    g3d_batch_unlock(fd2);
    CHECK(g3d_batch_scene_state(out, "a", &st) == G3D_BATCH_FAILED);
    CHECK(st.error && !strcmp(st.error, "x.png: broken"));
    g3d_batch_status_free(&st);
    free(work);

    g3d_batch_state states[2] = {G3D_BATCH_FAILED, G3D_BATCH_PENDING};
    char *errors[2] = {"x.png: broken", NULL};
    CHECK_OK(g3d_batch_summary_write(out, &b, states, errors, 2.5));
    char sum[600];
    snprintf(sum, sizeof sum, "%s/summary.json", out);
    unsigned char *text;
    size_t n;
    CHECK_OK(g3d_read_file(sum, 1 << 20, &text, &n));
    CHECK(strstr((char *)text, "\"failed\":\t1") && strstr((char *)text, "\"pending\":\t1"));
    free(text);
    g3d_batch_manifest_free(&b);
    g3d_batch_manifest_free(&b2);
}

TEST(slurm_script)
{
    const int tasks[] = {0, 1, 2, 5, 7, 8};
    const char *sargs[] = {"--account=lab"};
    const char *bargs[] = {"--retry-failed"};
    g3d_batch_slurm s = {"/opt/gen3d/bin/gen3d", "/data/it's here/m.jsonl", NULL, "/scratch/out", NULL, "gpu", "1:00:00",
                         "gpu:1", 8, 10, tasks, G3D_COUNTOF(tasks), sargs, 1, bargs, 1};
    char *text = NULL;
    CHECK_OK(g3d_batch_slurm_script(&s, &text));
    CHECK(text && strstr(text, "#SBATCH --array=0-2,5,7-8\n"));
    CHECK(text && strstr(text, "#SBATCH --cpus-per-task=8\n") && strstr(text, "#SBATCH --gres=gpu:1\n") &&
          strstr(text, "#SBATCH --partition=gpu\n") && strstr(text, "#SBATCH --time=1:00:00\n") &&
          strstr(text, "#SBATCH --account=lab\n") && strstr(text, "#SBATCH --output=/scratch/out/slurm/%A_%a.out\n"));
    CHECK(text && strstr(text, "'/data/it'\\''s here/m.jsonl'"));   /* quoted for sh */
    CHECK(text && strstr(text, "--shard \"$SLURM_ARRAY_TASK_ID/10\"") && strstr(text, "'--retry-failed'"));
    CHECK(text && !strstr(text, "--defaults"));
    free(text);
    /* the script run by sh gives each argument back unchanged */
    const char *d = dir_with("batch_slurm_script");
    char path[512], fake[512], args[512];
    snprintf(fake, sizeof fake, "%s/fake-gen3d", d);
    snprintf(args, sizeof args, "%s/args", d);
    snprintf(path, sizeof path, "%s/batch.sbatch", d);
    char body[1024];
    snprintf(body, sizeof body, "#!/bin/sh\nfor a in \"$@\"; do echo \"$a\"; done > '%s'\n", args);
    write_text(fake, body);
    chmod(fake, 0755);
    s.exe = fake;
    CHECK_OK(g3d_batch_slurm_script(&s, &text));
    write_text(path, text ? text : "");
    free(text);
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "SLURM_ARRAY_TASK_ID=7 SLURM_CPUS_PER_TASK=8 sh '%s'", path);
    CHECK(system(cmd) == 0);
    unsigned char *got;
    size_t n;
    CHECK_OK(g3d_read_file(args, 1 << 16, &got, &n));
    CHECK(got && !strcmp((char *)got, "batch\n/data/it's here/m.jsonl\n-o\n/scratch/out\n--shard\n7/10\n--jobs\n1\n-t\n8\n--retry-failed\n"));
    free(got);
    /* a line break would end the #SBATCH line and start a command */
    s.partition = "gpu\nrm -rf /";
    CHECK(g3d_batch_slurm_script(&s, &text) == G3D_ERR_ARG);
}

int main(void)
{
    RUN(manifest_values_defaults_and_paths);
    RUN(manifest_errors_per_line);
    RUN(shards);
    RUN(folder_states_and_locks);
    RUN(slurm_script);
    return test_summary();
}
