/* gen3d/base.h - status codes, error messages, logging, progress, RNG, atomic output.
 *
 * ERRORS
 *   Every fallible library function returns a g3d_status (G3D_OK == 0). On failure it
 *   records one line of English in a thread-local buffer (like errno / stbi_failure_reason):
 *   read it with g3d_error_message() before the next library call on the same thread.
 *   Messages name the file and the problem: "depth.png: 16-bit PNG expected, got 8-bit".
 *   Library code never prints and never exits; the CLI decides how to report.
 *
 *   Inside the library, fail with one line:
 *       return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated header", path);
 *   In debug builds the message is prefixed with the source location that raised it.
 *
 * LOGGING
 *   g3d_log() goes to a process-wide callback (stderr by default). The CLI sets the level
 *   from -q / -v. Set it once at start-up, before any threads run.
 *
 * PROGRESS
 *   Long operations take a g3d_progress (fn, user) pair in their params; a NULL fn is
 *   silent. g3d_progress_term() builds the terminal reporter the CLI uses.
 */
#ifndef G3D_BASE_H
#define G3D_BASE_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------------------
 * Status codes
 * ------------------------------------------------------------------------------------- */
typedef enum g3d_status {
    G3D_OK = 0,
    G3D_ERR_IO,          /* a file could not be opened, read or written            */
    G3D_ERR_FORMAT,      /* a file is corrupt, truncated or not of the expected kind */
    G3D_ERR_UNSUPPORTED, /* valid, but a variant we do not handle                  */
    G3D_ERR_ARG,         /* a caller-supplied argument is out of range             */
    G3D_ERR_MISMATCH,    /* sizes/shapes of inputs disagree                         */
    G3D_ERR_NOMEM,       /* allocation failed or a size overflowed                  */
    G3D_ERR_MODEL,       /* checkpoint does not match the expected architecture     */
    G3D_ERR_INTERNAL,    /* a bug: an invariant did not hold                        */
    G3D_CANCELLED,       /* the caller asked the operation to stop (not a failure)  */
    G3D_STATUS_COUNT
} g3d_status;

/* Short name of a status ("io", "format", ...). Never NULL. */
const char *g3d_status_name(g3d_status s);

/* Records a formatted message for the calling thread and returns `code`. Use G3D_ERR. */
g3d_status g3d__error_set(g3d_status code, const char *where, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

#ifdef NDEBUG
#define G3D_ERR(code, ...) g3d__error_set((code), NULL, __VA_ARGS__)
#else
#define G3D_STR2_(x) #x
#define G3D_STR_(x) G3D_STR2_(x)
#define G3D_ERR(code, ...) g3d__error_set((code), __FILE__ ":" G3D_STR_(__LINE__), __VA_ARGS__)
#endif

/* The last message recorded on this thread ("" if none). Valid until the next error. */
const char *g3d_error_message(void);

/* Prefixes the current message with "prefix: " (e.g. the file name known only to a caller). */
void g3d_error_prefix(const char *prefix);

/* Clears the message of this thread. */
void g3d_error_clear(void);

/* Convenience: G3D_TRY(expr) returns expr's status from the enclosing function on failure. */
#define G3D_TRY(expr) do { g3d_status g3d_rc_ = (expr); if (g3d_rc_ != G3D_OK) return g3d_rc_; } while (0)

/* ---------------------------------------------------------------------------------------
 * Checked sizes and allocation
 * ------------------------------------------------------------------------------------- */
/* Largest image side any reader accepts; larger headers are rejected as absurd. */
#define G3D_MAX_IMAGE_SIDE 32768

/* *out = a*b; returns 0 on overflow (out untouched), 1 otherwise. */
int g3d_size_mul(size_t a, size_t b, size_t *out);
/* *out = a*b*c; returns 0 on overflow. */
int g3d_size_mul3(size_t a, size_t b, size_t c, size_t *out);

/* calloc of n*size bytes with overflow check; NULL (and an NOMEM message) on failure.
 * Free with free(). `what` names the buffer in the message. */
void *g3d_calloc(size_t n, size_t size, const char *what);

/* ---------------------------------------------------------------------------------------
 * Logging
 * ------------------------------------------------------------------------------------- */
typedef enum g3d_log_level {
    G3D_LOG_ERROR = 0,
    G3D_LOG_WARN  = 1,
    G3D_LOG_INFO  = 2,
    G3D_LOG_DEBUG = 3
} g3d_log_level;

typedef void (*g3d_log_fn)(void *user, g3d_log_level level, const char *msg);

/* Redirects all logging; fn NULL restores the default (stderr). Not thread-safe: call at start. */
void g3d_log_set(g3d_log_fn fn, void *user);
/* Messages above `level` are dropped. Default: G3D_LOG_INFO. */
void g3d_log_set_level(g3d_log_level level);
g3d_log_level g3d_log_get_level(void);
void g3d_log(g3d_log_level level, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* ---------------------------------------------------------------------------------------
 * Progress
 * ------------------------------------------------------------------------------------- */
/* Called with the stage name, the step just finished (0..total) and the total (0 = unknown).
 * `info` is an optional short status text ("loss 0.031 psnr 24.1"), may be NULL. Returning
 * non-zero asks the operation to stop early: it then returns G3D_CANCELLED. */
typedef int (*g3d_progress_fn)(void *user, const char *stage, int64_t step, int64_t total,
                               const char *info);
typedef struct g3d_progress {
    g3d_progress_fn fn; /* NULL = silent */
    void *user;
} g3d_progress;

/* Reports through p if set; returns non-zero when the callback asked to stop. */
int g3d_progress_report(const g3d_progress *p, const char *stage, int64_t step, int64_t total,
                        const char *info);

/* A cancel request polled by long runs (e.g. set from a signal handler or another thread):
 * returning non-zero stops the run, which then returns G3D_CANCELLED. A NULL fn never cancels. */
typedef struct g3d_cancel {
    int (*fn)(void *user);
    void *user;
} g3d_cancel;

/* 1 when c is set and its callback asks to stop, else 0. */
int g3d_cancel_requested(const g3d_cancel *c);

/* The terminal reporter: on a TTY it redraws one line "stage  step/total  rate/s  ETA"; to
 * anything else (a pipe, a file), and when quiet, it prints nothing. `state` must outlive the
 * returned g3d_progress. */
typedef struct g3d_progress_term {
    FILE *out;
    int is_tty, quiet;
    char stage[64];
    double t_stage, t_last;
    int64_t first_step;  /* step at the stage's first report: the rate counts from there */
} g3d_progress_term;
g3d_progress g3d_progress_term_init(g3d_progress_term *state, FILE *out, int quiet);

/* Process set-up for programs (the CLI, benchmarks); call first thing in main.
 *  - glibc keeps large freed blocks instead of returning them to the kernel (no page faults
 *    each time a big temporary is allocated again);
 *  - idle OpenMP threads sleep instead of spinning: unless OMP_WAIT_POLICY or GOMP_SPINCOUNT
 *    is set, sets OMP_WAIT_POLICY=passive and re-executes the program with the same argv
 *    (returns only when that is not possible). Spinning threads take the cores from threads
 *    that still have work whenever the machine runs anything else: inference on two busy
 *    cores was three times slower. */
void g3d_process_setup(char **argv);

/* Seconds on a monotonic clock. */
double g3d_time_now(void);

/* ---------------------------------------------------------------------------------------
 * Deterministic random numbers (PCG32). Never seeded from global state.
 * ------------------------------------------------------------------------------------- */
typedef struct g3d_rng { uint64_t state, inc; } g3d_rng;
void     g3d_rng_seed(g3d_rng *r, uint64_t seed, uint64_t stream);
uint32_t g3d_rng_u32(g3d_rng *r);
/* Uniform in [0, 1). */
float    g3d_rng_float(g3d_rng *r);
/* Uniform integer in [0, n), n > 0, unbiased. */
uint32_t g3d_rng_below(g3d_rng *r, uint32_t n);
/* Standard normal (Box-Muller). */
float    g3d_rng_normal(g3d_rng *r);

/* ---------------------------------------------------------------------------------------
 * Atomic output: write to a temporary name in the same folder, rename on commit.
 * A failed or abandoned write leaves nothing behind under the final name.
 * ------------------------------------------------------------------------------------- */
typedef struct g3d_atomic_file {
    FILE *fp;            /* write here */
    char *path;          /* final name  (owned) */
    char *tmp_path;      /* temporary name (owned) */
} g3d_atomic_file;

/* Opens a temporary file next to `path` for binary writing. */
g3d_status g3d_atomic_open(g3d_atomic_file *af, const char *path);
/* Flushes, checks for write errors, renames onto the final name; frees af's strings.
 * On failure the temporary file is removed and the final name is untouched. */
g3d_status g3d_atomic_commit(g3d_atomic_file *af);
/* Closes and removes the temporary file; safe on a zeroed or already-finished struct. */
void g3d_atomic_abort(g3d_atomic_file *af);

/* Writes `n` bytes to `path` atomically. */
g3d_status g3d_write_file_atomic(const char *path, const void *data, size_t n);

/* Atomic output folders: g3d_atomic_dir_begin creates "<path>.tmp-<pid>" holding only the
 * marker file G3D_OUTPUT_MARKER and returns its name in *tmp_out (caller frees); the caller
 * writes files into it, then g3d_atomic_dir_commit moves it to `path`. An existing `path` is
 * replaced only if it is empty or an earlier gen3d output (has the marker); any other folder
 * is an error, so a mistyped -o never deletes a user's files. g3d_atomic_dir_abort removes the
 * temporary folder. */
#define G3D_OUTPUT_MARKER ".gen3d"
g3d_status g3d_atomic_dir_begin(const char *path, char **tmp_out);
g3d_status g3d_atomic_dir_commit(const char *tmp, const char *path);
void       g3d_atomic_dir_abort(const char *tmp);

/* Sorts n floats ascending, in place. */
void g3d_sort_f32(float *v, size_t n);
/* Median of n >= 1 floats (the middle value, or the mean of the two middle ones); sorts v in
 * place. */
float g3d_median_f32(float *v, size_t n);

/* Reads a whole file into a malloc'd buffer (+1 NUL byte not counted in *n). Caller frees.
 * Files above max_bytes are rejected (G3D_ERR_FORMAT). */
g3d_status g3d_read_file(const char *path, size_t max_bytes, unsigned char **data, size_t *n);

/* Joins folder and name with '/' into a malloc'd string. */
char *g3d_path_join(const char *dir, const char *name);
/* Creates a folder and its parents (like mkdir -p). */
g3d_status g3d_mkdirs(const char *path);
/* Removes a folder tree (files and sub-folders). Missing path is OK. */
g3d_status g3d_remove_tree(const char *path);
/* Extension of a path in lower case without the dot, into buf ("" if none). */
const char *g3d_path_ext(const char *path, char *buf, size_t bufsize);

#ifdef __cplusplus
}
#endif
#endif /* G3D_BASE_H */
