/* bench_twin.h - helpers of the benchmarks that race a PyTorch twin process (bench_lama.c,
 * bench_sam.c, bench_depth.c): CPU time, the median of the rounds, starting the twin with pipes,
 * the load average. */
#ifndef G3D_BENCH_TWIN_H
#define G3D_BENCH_TWIN_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

static inline double cpu_seconds(void)
{
    struct rusage r;
    getrusage(RUSAGE_SELF, &r);
    return (double)r.ru_utime.tv_sec + r.ru_stime.tv_sec + 1e-6 * ((double)r.ru_utime.tv_usec + r.ru_stime.tv_usec);
}

static inline int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static inline double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* The twin as a child process: its stdin and stdout are ours to write and read. */
static inline pid_t spawn(char *const argv[], FILE **to, FILE **from)
{
    int in[2], out[2];
    if (pipe(in) || pipe(out)) return -1;
    pid_t pid = fork();
    if (pid == 0) {
        dup2(in[0], 0);
        dup2(out[1], 1);
        close(in[1]);
        close(out[0]);
        execv(argv[0], argv);
        _exit(127);
    }
    close(in[0]);
    close(out[1]);
    *to = fdopen(in[1], "w");
    *from = fdopen(out[0], "r");
    return pid;
}

/* Starts argv (NULL-ended, argv[0] a path) as a twin and waits for its "ready". Returns 0, or 1
 * after saying why. */
static inline int twin_spawn(char *const argv[], FILE **to, FILE **from, pid_t *pid)
{
    *pid = spawn(argv, to, from);
    char line[256] = "";
    if (*pid < 0 || !*to || !*from || !fgets(line, sizeof line, *from) || strncmp(line, "ready", 5)) {
        fprintf(stderr, "the PyTorch twin %s did not start (/usr/bin/python3 with torch is needed, and the official "
                        "checkout where the twin imports it)\n", argv[1]);
        return 1;
    }
    return 0;
}

/* Starts the twin `/usr/bin/python3 SCRIPT CHECKOUT SAVE ARGS...` (args: up to 4, NULL-ended)
 * with SAVE a fresh temporary file (its name into save[32]) that the twin fills with its weights,
 * and waits for its "ready". Returns 0, or 1 after saying why (save removed). */
static inline int twin_start(const char *script, const char *checkout, const char *const *args, char save[32], FILE **to,
                      FILE **from, pid_t *pid)
{
    snprintf(save, 32, "/tmp/bench_twin_XXXXXX");
    int fd = mkstemp(save);
    if (fd < 0) return 1;
    close(fd);
    char *argv[9] = {"/usr/bin/python3", (char *)script, (char *)checkout, save};
    for (int i = 0; i < 4 && args && args[i]; i++) argv[4 + i] = (char *)args[i];
    if (twin_spawn(argv, to, from, pid)) {
        unlink(save);
        return 1;
    }
    return 0;
}

/* The 1-minute load average of the machine (what else ran during a measurement). */
static inline double load_average(void)
{
    double l = -1;
    FILE *f = fopen("/proc/loadavg", "r");
    if (f) {
        if (fscanf(f, "%lf", &l) != 1) l = -1;
        fclose(f);
    }
    return l;
}

/* One forward of the twin: its wall and CPU seconds; 0 on success. */
static inline int twin_round(FILE *to, FILE *from, double *wall, double *cpu)
{
    char line[256];
    fprintf(to, "go\n");
    fflush(to);
    return !fgets(line, sizeof line, from) || sscanf(line, "torch_seconds %lf %lf", wall, cpu) != 2;
}

/* Ends the twin: closes its pipes (its loop over stdin ends) and waits for it. */
static inline void twin_stop(FILE *to, FILE *from, pid_t pid)
{
    fclose(to);
    fclose(from);
    waitpid(pid, NULL, 0);
}

#endif
