/* bench_twin.h - helpers of the benchmarks that race a PyTorch twin process (bench_lama.c,
 * bench_sam.c): CPU time, the median of the rounds, starting the twin with pipes. */
#ifndef G3D_BENCH_TWIN_H
#define G3D_BENCH_TWIN_H

#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

static double cpu_seconds(void)
{
    struct rusage r;
    getrusage(RUSAGE_SELF, &r);
    return (double)r.ru_utime.tv_sec + r.ru_stime.tv_sec + 1e-6 * ((double)r.ru_utime.tv_usec + r.ru_stime.tv_usec);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* The twin as a child process: its stdin and stdout are ours to write and read. */
static pid_t spawn(char *const argv[], FILE **to, FILE **from)
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

#endif
