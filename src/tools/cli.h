/* cli.h - what every gen3d command shares: the command record, an option table that drives
 * both parsing and --help, the common flags, and error reporting.
 *
 * A command lives in src/tools/cmd_<name>.c and defines
 *     const g3d_command g3d_cmd_<name> = {"name", "one-line summary", run_fn};
 * The build generates the command table from the file names.
 *
 * Exit codes: 0 success, 1 the work failed (bad input file, I/O error, ...), 2 usage error,
 * 130 interrupted (Ctrl-C; the run stopped cleanly and left no output).
 * Results (paths written) go to stdout; logs and progress to stderr.
 */
#ifndef G3D_CLI_H
#define G3D_CLI_H

#include "gen3d/base.h"

#include <stddef.h>
#include <stdint.h>

enum { G3D_EXIT_OK = 0, G3D_EXIT_FAIL = 1, G3D_EXIT_USAGE = 2, G3D_EXIT_CANCELLED = 130 };

typedef struct g3d_command {
    const char *name;
    const char *summary;
    int (*run)(int argc, char **argv); /* argv[0] is the command name */
} g3d_command;

typedef enum g3d_opt_kind {
    G3D_OPT_FLAG,    /* int, set to 1 */
    G3D_OPT_INT,     /* int */
    G3D_OPT_INT64,   /* int64_t */
    G3D_OPT_DOUBLE,  /* double */
    G3D_OPT_STRING,  /* const char *, points into argv */
    G3D_OPT_PATH,    /* a string naming a file or folder (a batch manifest resolves it) */
    G3D_OPT_TRAJECTORY /* a string: a camera-path preset (trajectory.h) or a camera file */
} g3d_opt_kind;

typedef struct g3d_opt {
    char short_name;        /* 0 = none */
    const char *long_name;  /* without the dashes */
    g3d_opt_kind kind;
    void *target;
    const char *metavar;    /* "N", "FILE", ... (ignored for flags) */
    const char *help;       /* one line; the current value of target is shown as the default */
} g3d_opt;

/* Flags every command accepts. */
typedef struct g3d_cli_common {
    const char *output;  /* -o */
    int64_t seed;        /* -s; negative = random (the seed used is printed and recorded) */
    int threads;         /* -t; 0 = all cores */
    int quiet, verbose;  /* -q, -v */
} g3d_cli_common;

#define G3D_COMMON_OPTS(c)                                                                       \
    {'o', "output", G3D_OPT_STRING, &(c)->output, "PATH", "output file or folder"},              \
    {'s', "seed", G3D_OPT_INT64, &(c)->seed, "N", "random seed (negative: pick one at random)"}, \
    {'t', "threads", G3D_OPT_INT, &(c)->threads, "N", "worker threads (0: all cores)"},          \
    {'q', "quiet", G3D_OPT_FLAG, &(c)->quiet, NULL, "no progress or info messages"},             \
    {'v', "verbose", G3D_OPT_FLAG, &(c)->verbose, NULL, "debug messages"}

/* Defaults for the common flags: seed 0, all threads. */
void g3d_cli_common_init(g3d_cli_common *c);

/* Applies the common flags: log level, thread count, and resolves a negative seed to a
 * random one. Prints "seed: N" at info level. */
void g3d_cli_common_apply(g3d_cli_common *c);

/* Parses argv[1..] against opts. Positional arguments are collected into pos (up to max_pos).
 * `usage` is the synopsis line ("gen3d info FILE"), `description` a paragraph printed by --help.
 * Returns G3D_EXIT_OK to continue, -1 when --help was printed (caller returns 0), or
 * G3D_EXIT_USAGE after printing one error line. */
int g3d_cli_parse(int argc, char **argv, const g3d_opt *opts, int nopts, const char *usage,
                  const char *description, const char **pos, int max_pos, int *npos);

/* Sets the option whose long name is `name` from the text `value` as the command line would
 * ("0" clears a flag, anything else sets it). Returns G3D_EXIT_OK, or G3D_EXIT_USAGE after
 * reporting an unknown name or a bad value. */
int g3d_cli_set_option(const g3d_opt *opts, int nopts, const char *name, const char *value);

/* While buf is non-NULL, g3d_cli_errorf keeps its message in buf (the first one since the
 * call, cleared here) instead of printing it: a caller can check options and word the report
 * itself. NULL prints again. */
void g3d_cli_capture_errors(char *buf, size_t n);

/* Prints "gen3d: error: <message>" (the thread's last error) and returns G3D_EXIT_FAIL; for
 * G3D_CANCELLED prints "gen3d: interrupted" and returns G3D_EXIT_CANCELLED. */
int g3d_cli_fail(g3d_status rc);
/* Prints "gen3d: error: <formatted message>" and returns `code`. */
int g3d_cli_errorf(int code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* The progress reporter for this process (stderr; silent with -q). Valid after
 * g3d_cli_common_apply. */
g3d_progress g3d_cli_progress(void);

/* A cancel request raised by the first SIGINT (Ctrl-C) or SIGTERM, so that a long run stops at
 * its next step and removes what it was writing; a second signal ends the process at once.
 * The handlers are installed by the first call. */
g3d_cancel g3d_cli_cancel(void);

#define G3D_COUNTOF(a) ((int)(sizeof(a) / sizeof((a)[0])))

#endif /* G3D_CLI_H */
