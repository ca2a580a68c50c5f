/* gen3d/batch.h - many scenes from one manifest: the manifest (JSON Lines, one scene per line),
 * the batch output folder and each scene's status file, shards of a manifest, and the Slurm
 * job-array script. Running the scenes (processes, threads, progress) is the caller's: `gen3d
 * batch` runs each scene through g3d_generate (generate.h). docs/batch.md has the format.
 *
 * THE OUTPUT FOLDER
 *     DIR/batch.json           which manifest (and defaults file) the folder belongs to
 *     DIR/<id>/                one scene, moved into place whole: the scene's files and
 *                              status.json (done or failed, the error, seconds per stage, the
 *                              options used)
 *     DIR/summary.json         every scene's state at the end of the last run (or shard)
 *     DIR/.batch/locks/<id>    held (flock) while a process works on the scene: "running"
 *     DIR/.batch/work/         scenes being built, under temporary names
 *     DIR/slurm/               the job-array script and the tasks' logs
 * A scene's state is read from these alone, so it can be asked from any node of a cluster
 * while other processes work (the locks need a file system with working flock, as NFS has).
 */
#ifndef G3D_BATCH_H
#define G3D_BATCH_H

#include "gen3d/base.h"
#include "gen3d/generate.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- the manifest ---------------------------------------------------------------------------- */

/* What a manifest key holds. A PATH value is resolved against the folder of the file it comes
 * from and must exist; a NAME_OR_PATH value is kept as it is when it is one of the key's names,
 * and is a PATH otherwise. */
typedef enum g3d_batch_kind {
    G3D_BATCH_FLAG,         /* true / false */
    G3D_BATCH_INT,          /* a whole number */
    G3D_BATCH_NUMBER,       /* any finite number */
    G3D_BATCH_STRING,
    G3D_BATCH_PATH,
    G3D_BATCH_NAME_OR_PATH
} g3d_batch_kind;

typedef struct g3d_batch_key {
    const char *name;
    g3d_batch_kind kind;
    const char *const *names;   /* NAME_OR_PATH: the names (NULL-terminated); else NULL */
} g3d_batch_key;

typedef struct g3d_batch_option {
    char *key;     /* a key of the table the manifest was read with */
    char *value;   /* as text: "1"/"0" for flags, numbers as written, paths resolved */
} g3d_batch_option;

typedef struct g3d_batch_scene {
    int index;                 /* 0-based among the manifest's non-blank lines: the shard key */
    int line;                  /* 1-based line number in the manifest */
    char *id;                  /* NULL when the line has no usable id */
    char *error;               /* NULL, or why the line cannot run ("unknown key 'x'") */
    int nopts;
    g3d_batch_option *opts;    /* the defaults' keys then the line's, one entry per key */
} g3d_batch_scene;

typedef struct g3d_batch_manifest {
    char *path;                /* absolute */
    char *defaults;            /* absolute, or NULL */
    int nscenes;
    g3d_batch_scene *scenes;   /* one per non-blank line, in order */
} g3d_batch_manifest;

/* Reads a manifest: one JSON object per non-blank line with "id" (letters, digits, '.', '_',
 * '-'; not starting with '.') and keys from `keys`; `defaults` (optional) is a file holding one
 * JSON object of the same keys (no "id") that every line starts from. A bad line (not JSON, an
 * unknown key, a value of the wrong type, a missing file, a duplicate id) gets its `error` and
 * the other lines are read on. Fails (nothing in m) only when a file cannot be used at all:
 * unreadable, empty, or a defaults file that is bad. m is freed by g3d_batch_manifest_free. */
g3d_status g3d_batch_manifest_load(const char *path, const char *defaults, const g3d_batch_key *keys,
                                   int nkeys, g3d_batch_manifest *m);
void g3d_batch_manifest_free(g3d_batch_manifest *m);

/* Records why a scene cannot run (the first reason is kept). Returns G3D_ERR_NOMEM or G3D_OK. */
g3d_status g3d_batch_scene_set_error(g3d_batch_scene *s, const char *message);
/* The scene's value of `key`, or NULL. */
const char *g3d_batch_scene_get(const g3d_batch_scene *s, const char *key);
/* Lines with an error. */
int g3d_batch_manifest_bad(const g3d_batch_manifest *m);

/* ---- shards ---------------------------------------------------------------------------------- */

/* Parses "K/N" (0 <= K < N). G3D_ERR_ARG when malformed. */
g3d_status g3d_batch_shard_parse(const char *text, int *k, int *n);
/* Inside a Slurm array task: the shard from SLURM_ARRAY_TASK_ID (counted from
 * SLURM_ARRAY_TASK_MIN) and SLURM_ARRAY_TASK_COUNT (else MAX - MIN + 1), which fits arrays of
 * consecutive indices (--array=0-N). Returns 1 and sets k, n there; 0 (k = 0, n = 1) outside
 * an array; -1 when the variables are malformed or disagree. */
int g3d_batch_shard_from_env(int *k, int *n);
/* 1 when the scene with this index belongs to shard k of n (index mod n == k). */
int g3d_batch_in_shard(int index, int k, int n);

/* ---- the output folder ----------------------------------------------------------------------- */

typedef enum g3d_batch_state {
    G3D_BATCH_PENDING,   /* nothing yet (or an unfinished attempt) */
    G3D_BATCH_RUNNING,   /* a process holds the scene's lock */
    G3D_BATCH_DONE,
    G3D_BATCH_FAILED
} g3d_batch_state;

/* "pending", "running", "done", "failed". */
const char *g3d_batch_state_name(g3d_batch_state s);

/* Makes DIR a batch folder for manifest m (creates it and writes batch.json), or checks that it
 * is one already for the same manifest file. A folder that belongs to another manifest, or
 * that exists with files and no batch.json, is refused (G3D_ERR_ARG, naming both). */
g3d_status g3d_batch_folder_claim(const char *dir, const g3d_batch_manifest *m);
/* The manifest and defaults file (NULL when none) a batch folder belongs to; caller frees both. */
g3d_status g3d_batch_folder_manifest(const char *dir, char **manifest, char **defaults);

/* What a scene's status.json holds. */
typedef struct g3d_batch_status {
    g3d_batch_state state;
    char *error;                       /* failed: why (owned) */
    double seconds[G3D_STAGE_COUNT];   /* per stage; 0 for stages not reached */
    double seconds_total;
} g3d_batch_status;

/* The state of scene `id` in DIR: RUNNING while its lock is held, else DONE or FAILED from
 * DIR/<id>/status.json, else PENDING. st (may be NULL) gets the status file's content; free
 * with g3d_batch_status_free. */
g3d_batch_state g3d_batch_scene_state(const char *dir, const char *id, g3d_batch_status *st);
void g3d_batch_status_free(g3d_batch_status *st);

/* Takes the scene's lock without waiting. Returns G3D_OK with *fd >= 0 when this process now
 * works on the scene, G3D_OK with *fd = -1 when another holds it, or an I/O error. The lock
 * goes with the process: g3d_batch_unlock, or its exit. */
g3d_status g3d_batch_lock(const char *dir, const char *id, int *fd);
void g3d_batch_unlock(int fd);

/* The folder a scene is built in, DIR/.batch/work/<id> (malloc'd); a leftover from an attempt
 * that died is removed first. Needs the scene's lock. */
char *g3d_batch_work_dir(const char *dir, const char *id);

/* Writes status.json into `folder` (the scene's work folder) for scene s: failed when `error`
 * is non-NULL, with seconds per stage (NULL: only the total), the thread count and s's
 * options. */
g3d_status g3d_batch_status_write(const char *folder, const g3d_batch_scene *s, const char *error,
                                  const double seconds[G3D_STAGE_COUNT], double seconds_total, int threads);

/* Moves a finished work folder to DIR/<id>, replacing an earlier result of that scene. */
g3d_status g3d_batch_commit(const char *dir, const char *id, const char *work);

/* Writes DIR/summary.json: the counts of each state and every scene's state (and error) as
 * `states` has them (one per scene of m; lines without an id are listed as bad lines). */
g3d_status g3d_batch_summary_write(const char *dir, const g3d_batch_manifest *m, const g3d_batch_state *states,
                                   char *const *errors, double seconds);

/* ---- Slurm ----------------------------------------------------------------------------------- */

typedef struct g3d_batch_slurm {
    const char *exe;              /* the gen3d program every task runs (absolute) */
    const char *manifest, *defaults, *output;   /* absolute; defaults may be NULL */
    const char *job_name;         /* NULL: "gen3d-batch" */
    const char *partition, *time, *gres;         /* NULL: the cluster's defaults */
    int cpus_per_task;            /* > 0 */
    int shards;                   /* N of --shard K/N */
    const int *tasks; int ntasks; /* the shards to run (array indices), ascending */
    const char *const *sbatch_args; int nsbatch_args;  /* extra "#SBATCH ARG" lines */
    const char *const *batch_args; int nbatch_args;    /* extra arguments of each task's gen3d batch */
} g3d_batch_slurm;

/* The text of a job-array script whose task K runs `gen3d batch MANIFEST -o DIR --shard K/N`
 * with one scene at a time on all the task's CPUs, logging to DIR/slurm/. *text is malloc'd. */
g3d_status g3d_batch_slurm_script(const g3d_batch_slurm *s, char **text);

#ifdef __cplusplus
}
#endif
#endif /* G3D_BATCH_H */
