/* Layer-library benchmark: each operator on the real shapes of the project's models, its
 * arithmetic rate, and that rate as a fraction of the machine's sgemm rate (OpenBLAS, 1536^3,
 * its own threads, the same thread count) measured in the same run: sgemm and the operator run
 * in alternation and the fraction is the median over rounds of operator rate / the sgemm rate
 * just before it, because a shared machine's speed drifts within seconds. Both sides are timed
 * on their own: OpenBLAS's threads are told to sleep as soon as a call ends and each part starts
 * after a short pause, so neither side's idle threads spin on the cores while the other runs.
 *   cmake --build build --target bench && ./build/bench_nn [filter] [--reps N]
 * `filter` keeps the cases whose name contains it. Work counts are multiply-adds x 2 of the
 * operator's definition (also for Winograd, which does fewer). A last table sums up per op
 * kind (linear, attention, conv3, conv3w, conv1, convT, ...): the median and lowest fraction.
 * Operators that do a few operations per value they read (depthwise convolution, norms,
 * activations) are bound by memory, not arithmetic: their own table gives the bytes they must
 * move (each input read once, each output written once) per second, as a fraction of a
 * streaming pass y = a x + b over as many bytes, timed in alternation the same way. */
#include "gen3d/nn.h"

#include <cblas.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static int g_reps = 5, g_threads, g_ran;
static const char *g_filter;
static float *g_a, *g_b, *g_c;

/* Per op kind (the first word of a case's name): the cases' fractions of their reference
 * (sgemm, or the streaming pass for memory-bound kinds), for the summaries. */
#define MAX_KINDS 16
static struct {
    char name[16];
    int n, memory;
    double frac[64];
} g_kinds[MAX_KINDS];
static int g_nkinds, g_mem_header;
static double g_sgemm_lo = 1e30, g_sgemm_hi, g_stream_lo = 1e30, g_stream_hi;

static void note_kind(const char *name, int memory, double frac)
{
    char k[16];
    snprintf(k, sizeof k, "%.*s", (int)strcspn(name, " "), name);
    int i = 0;
    while (i < g_nkinds && strcmp(g_kinds[i].name, k)) i++;
    if (i == MAX_KINDS) return;
    if (i == g_nkinds) snprintf(g_kinds[g_nkinds++].name, sizeof g_kinds[i].name, "%s", k);
    g_kinds[i].memory = memory;
    if (g_kinds[i].n < 64) g_kinds[i].frac[g_kinds[i].n++] = frac;
}

static float *rnd(size_t n, float scale)
{
    float *p = malloc(sizeof(float) * n);
    g3d_rng r;
    g3d_rng_seed(&r, n, 7);
    for (size_t i = 0; i < n; i++) p[i] = scale * (2.0f * g3d_rng_float(&r) - 1.0f);
    return p;
}

static double cpu_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* GFLOP/s of one 1536^3 sgemm (about 35 ms at full speed), in wall time and (*cpu_rate) in
 * the CPU time of the process */
static double sgemm_rate(double *cpu_rate)
{
    const int n = 1536;
    double t0 = g3d_time_now(), c0 = cpu_now();
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, n, n, 1.0f, g_a, n, g_b, n, 0.0f, g_c, n);
    *cpu_rate = 2.0 * n * n * n / (cpu_now() - c0) * 1e-9;
    return 2.0 * n * n * n / (g3d_time_now() - t0) * 1e-9;
}

/* GB/s of one pass y = 1.5 x + 0.5 over n floats (n read, n written) on the same threads */
static double stream_rate(const float *x, float *y, long n, double *cpu_rate)
{
    double t0 = g3d_time_now(), c0 = cpu_now();
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; i++) y[i] = 1.5f * x[i] + 0.5f;
    *cpu_rate = 8.0 * n / (cpu_now() - c0) * 1e-9;
    return 8.0 * n / (g3d_time_now() - t0) * 1e-9;
}

typedef void (*case_fn)(void *ctx);

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Idle OpenMP threads spin for a few milliseconds before they sleep (libgomp's default); a
 * pause before each timed part keeps the previous part's threads off the cores. */
static void settle(void)
{
    struct timespec t = {0, 20 * 1000 * 1000};
    nanosleep(&t, NULL);
}

static void mem_header(void)
{
    if (g_mem_header++) return;
    printf("\nmemory-bound operators (bytes each must move, against a streaming pass over as many):\n");
    printf("| %-26s | %-36s | %8s | %9s | %9s | %7s | %7s | %9s |\n", "operator", "shape", "MB", "ms", "cpu ms",
           "GB/s", "stream", "stream cpu");
    printf("|%s|%s|%s|%s|%s|%s|%s|%s|\n", "----------------------------", "--------------------------------------",
           "----------", "-----------", "-----------", "---------", "---------", "------------");
}

/* Times fn against its reference in alternation: each round runs the reference (one sgemm, or
 * for a memory-bound operator, bytes > 0, a streaming pass over as many bytes) and then fn
 * (repeated to last at least ~50 ms); the row shows the median wall and CPU time of fn (CPU
 * time of all threads, so about threads x wall when they are all busy) and the median over
 * rounds of (rate of fn) / (rate of the reference just before it), which cancels most of the
 * drift of a shared machine, in wall time and in CPU time (the steadier one while other jobs
 * take turns on the cores: a part that waits for a core is not charged for the wait). An
 * operator with neither flops nor bytes (the FFTs) is timed alone. */
static void run(const char *name, const char *shape, double flops, double bytes, case_fn fn, void *ctx)
{
    if (g_filter && !strstr(name, g_filter)) return;
    const int memory = flops <= 0;
    const double work = memory ? bytes : flops;
    const long sn = (long)(bytes / 8);
    float *sx = NULL, *sy = NULL;
    if (sn > 0) {
        sx = malloc(sizeof(float) * sn), sy = malloc(sizeof(float) * sn);
        if (!sx || !sy) {
            fprintf(stderr, "bench_nn: out of memory\n");
            exit(1);
        }
        for (long i = 0; i < sn; i++) sx[i] = (float)(i & 1023), sy[i] = 0.0f;
    }
    if (memory) mem_header();
    double t0 = g3d_time_now();
    fn(ctx); /* warm-up: first-touch of buffers, FFT plans */
    double once = g3d_time_now() - t0;
    int inner = once >= 0.05 ? 1 : (int)(0.05 / (once > 1e-6 ? once : 1e-6)) + 1;
    double t[64], cpu[64], ratio[64], cratio[64];
    int reps = g_reps < 64 ? g_reps : 64;
    for (int r = 0; r < reps; r++) {
        settle();
        double cbase = 1, base = 1;
        if (!memory) {
            base = sgemm_rate(&cbase);
            g_sgemm_lo = base < g_sgemm_lo ? base : g_sgemm_lo;
            g_sgemm_hi = base > g_sgemm_hi ? base : g_sgemm_hi;
        } else if (sn > 0) {
            base = stream_rate(sx, sy, sn, &cbase);
            g_stream_lo = base < g_stream_lo ? base : g_stream_lo;
            g_stream_hi = base > g_stream_hi ? base : g_stream_hi;
        }
        settle();
        t0 = g3d_time_now();
        double c0 = cpu_now();
        for (int i = 0; i < inner; i++) fn(ctx);
        t[r] = (g3d_time_now() - t0) / inner;
        cpu[r] = (cpu_now() - c0) / inner;
        ratio[r] = work / t[r] * 1e-9 / base;
        cratio[r] = work / cpu[r] * 1e-9 / cbase;
    }
    qsort(t, reps, sizeof *t, cmp_double);
    qsort(cpu, reps, sizeof *cpu, cmp_double);
    qsort(ratio, reps, sizeof *ratio, cmp_double);
    qsort(cratio, reps, sizeof *cratio, cmp_double);
    double tm = t[reps / 2], cm = cpu[reps / 2], rm = ratio[reps / 2], crm = cratio[reps / 2];
    g_ran++;
    if (work > 0) {
        note_kind(name, memory, rm);
        printf("| %-26s | %-36s | %8.2f | %9.2f | %9.2f | %7.1f | %5.0f %% | %*.0f %% |\n", name, shape,
               memory ? work * 1e-6 : work * 1e-9, tm * 1e3, cm * 1e3, work / tm * 1e-9, 100.0 * rm, memory ? 8 : 7,
               100.0 * crm);
    } else {
        printf("| %-26s | %-36s | %8s | %9.2f | %9.2f | %7s | %7s | %10s |\n", name, shape, "-", tm * 1e3, cm * 1e3, "-",
               "-", "-");
    }
    fflush(stdout);
    free(sx), free(sy);
}

static void check(g3d_status rc)
{
    if (rc != G3D_OK) {
        fprintf(stderr, "bench_nn: %s\n", g3d_error_message());
        exit(1);
    }
}

/* ---- linear ------------------------------------------------------------------------------- */
typedef struct lin_case {
    g3d_nn_lin L;
    float *x, *y, *w, *b, *gamma;
    int n, in, out, legacy;
    g3d_nn_epi epi;
} lin_case;

static void lin_fn(void *p)
{
    lin_case *c = p;
    if (c->legacy)
        g3d_nn_linear(c->x, c->n, c->in, c->w, c->b, c->out, c->y);
    else
        check(g3d_nn_lin_forward(&c->L, c->x, c->n, 0, c->y, 0, &c->epi));
}

static void lin(const char *name, int n, int in, int out, g3d_act act, int residual, g3d_dtype store, int legacy)
{
    if (g_filter && !strstr(name, g_filter)) return;
    lin_case c = {.n = n, .in = in, .out = out, .legacy = legacy};
    c.x = rnd((size_t)n * in, 1.0f), c.y = rnd((size_t)n * out, 1.0f), c.w = rnd((size_t)in * out, 0.05f);
    c.b = rnd(out, 0.1f), c.gamma = rnd(out, 1.0f);
    check(g3d_nn_lin_init(&c.L, c.w, G3D_DT_F32, c.b, out, in, store));
    c.epi.act = act;
    if (residual) c.epi.scale = c.gamma, c.epi.res = c.y;
    char shape[64];
    snprintf(shape, sizeof shape, "%dx%d -> %d%s%s%s", n, in, out, act ? " +act" : "", residual ? " +ls+res" : "",
             store == G3D_DT_BF16 ? " bf16" : "");
    run(name, shape, 2.0 * n * in * out, 0, lin_fn, &c);
    g3d_nn_lin_free(&c.L);
    free(c.x), free(c.y), free(c.w), free(c.b), free(c.gamma);
}

/* ---- attention ---------------------------------------------------------------------------- */
typedef struct attn_case {
    g3d_nn_attn a;
} attn_case;

static void attn_fn(void *p)
{
    attn_case *c = p;
    check(g3d_nn_attend(&c->a));
}

static void attn(const char *name, int nq, int nk, int heads, int hd, int windows, int relpos, int grid)
{
    if (g_filter && !strstr(name, g_filter)) return;
    attn_case c;
    const int d = heads * hd;
    const size_t nqw = (size_t)nq * windows, nkw = (size_t)nk * windows;
    float *q = rnd(nqw * d, 1.0f), *k = rnd(nkw * d, 1.0f), *v = rnd(nkw * d, 1.0f);
    float *o = malloc(sizeof(float) * nqw * d), *rh = NULL, *rw = NULL, *relh = NULL;
    g3d_nn_bias_relpos rp = {0};
    /* windows: one batched call, problem b at row b*nq */
    c.a = (g3d_nn_attn){.nq = nq, .nk = nk, .heads = heads, .hd = hd, .q = q, .k = k, .v = v, .out = o,
                        .scale = 1.0f / sqrtf((float)hd), .batch = windows, .bsq = (long)nq * d,
                        .bsk = (long)nk * d, .bsv = (long)nk * d, .bso = (long)nq * d};
    if (relpos) {
        relh = rnd((size_t)(2 * grid - 1) * hd, 0.1f);
        size_t nt = (size_t)windows * heads * nq * grid;
        rh = malloc(sizeof(float) * nt), rw = malloc(sizeof(float) * nt);
        for (int b = 0; b < windows; b++)
            check(g3d_nn_relpos_tables(q + (size_t)b * nq * d, d, heads, hd, grid, grid, grid, grid, relh, relh,
                                       rh + (size_t)b * heads * nq * grid, rw + (size_t)b * heads * nq * grid));
        rp = (g3d_nn_bias_relpos){rh, rw, nq, grid, grid, heads};
        c.a.bias = g3d_nn_bias_relpos_fn, c.a.bias_ctx = &rp;
    }
    char shape[64];
    snprintf(shape, sizeof shape, "%d x %d tok, %dx%d%s%s", nq, nk, heads, hd, relpos ? " relpos" : "",
             windows > 1 ? " x25 win" : "");
    run(name, shape, 4.0 * nq * nk * d * windows, 0, attn_fn, &c);
    free(q), free(k), free(v), free(o), free(rh), free(rw), free(relh);
}

/* ---- convolution -------------------------------------------------------------------------- */
typedef struct conv_case {
    g3d_nn_conv c;
    float *x, *y;
    int h, w;
} conv_case;

static void conv_fn(void *p)
{
    conv_case *c = p;
    check(g3d_nn_conv_forward(&c->c, c->x, c->h, c->w, c->y, NULL));
}

/* prepare: g3d_nn_conv_prepare first (Winograd for 3x3 stride 1, phase kernels for transposed) */
static void conv(const char *name, int cin, int cout, int k, int stride, int pad, int h, int w, int groups,
                 g3d_nn_padmode mode, int transposed, int opad, int prepare)
{
    if (g_filter && !strstr(name, g_filter)) return;
    conv_case c = {.h = h, .w = w};
    size_t nw = (size_t)cin * cout / groups * k * k;
    float *wt = rnd(nw, 0.05f), *b = rnd(cout, 0.1f);
    c.c = g3d_nn_conv_make(cin, cout, k, stride, pad, wt, b);
    c.c.groups = groups, c.c.pad_mode = mode, c.c.transposed = transposed, c.c.output_padding = opad;
    if (prepare) check(g3d_nn_conv_prepare(&c.c));
    int ho, wo;
    check(g3d_nn_conv_out_size(&c.c, h, w, &ho, &wo));
    c.x = rnd((size_t)cin * h * w, 1.0f), c.y = malloc(sizeof(float) * (size_t)cout * ho * wo);
    double flops = transposed ? 2.0 * cin * cout * k * k * h * w : 2.0 * cout * (cin / groups) * k * k * ho * wo;
    /* a depthwise convolution does k*k multiply-adds per value it reads: bound by memory */
    const int depthwise = groups > 1 && groups == cin;
    const double bytes = depthwise ? 4.0 * ((double)cin * h * w + (double)cout * ho * wo) : 0;
    char shape[64];
    snprintf(shape, sizeof shape, "%s%dx%dx%d -> %d k%d s%d%s%s", transposed ? "T " : "", cin, h, w, cout, k, stride,
             groups > 1 ? " dw" : mode == G3D_PAD_REFLECT ? " reflect" : mode == G3D_PAD_REPLICATE ? " repl" : "",
             c.c.prep && !transposed ? " wino" : "");
    run(name, shape, depthwise ? 0 : flops, bytes, conv_fn, &c);
    g3d_nn_conv_release(&c.c);
    free(wt), free(b), free(c.x), free(c.y);
}

/* ---- memory-bound operators ------------------------------------------------------------------ */
typedef struct misc_case {
    int kind, c, h, w;
    float *x, *y, *g, *b;
} misc_case;

static void misc_fn(void *p)
{
    misc_case *m = p;
    switch (m->kind) {
    case 0: g3d_nn_groupnorm(m->x, m->c, m->h * m->w, 32, m->g, m->b, 1e-6f, G3D_ACT_SILU, m->y); break;
    case 1: g3d_nn_layernorm(m->x, m->h, m->c, m->g, m->b, 1e-6f, m->y); break;
    case 2: check(g3d_nn_rfft2(m->x, m->c, m->h, m->w, m->y)); break;
    case 3: check(g3d_nn_irfft2(m->y, m->c, m->h, m->w, m->x)); break;
    default: g3d_nn_activate(G3D_ACT_GELU, m->x, (size_t)m->c * m->h * m->w); break;
    }
}

static void misc(const char *name, const char *shape, int kind, int c, int h, int w)
{
    if (g_filter && !strstr(name, g_filter)) return;
    misc_case m = {.kind = kind, .c = c, .h = h, .w = w};
    size_t n = (size_t)c * h * (w + 2) * 2;
    m.x = rnd(n, 1.0f), m.y = rnd(n, 1.0f), m.g = rnd(c, 1.0f), m.b = rnd(c, 1.0f);
    /* the norms and GELU read and write c*h*w values once each; the FFTs are timed alone */
    const double bytes = kind == 2 || kind == 3 ? 0 : 8.0 * c * h * w;
    run(name, shape, 0, bytes, misc_fn, &m);
    free(m.x), free(m.y), free(m.g), free(m.b);
}

int main(int argc, char **argv)
{
    /* OpenBLAS's worker threads spin (yielding) for 2^28 cycles, about 0.1 s, after every call
     * unless OPENBLAS_THREAD_TIMEOUT says otherwise; they would share the cores with the operator
     * timed right after each sgemm. The variable is read when the library loads, hence the
     * re-exec (if it fails, the run goes on with the spinning threads). */
    if (!getenv("OPENBLAS_THREAD_TIMEOUT")) {
        setenv("OPENBLAS_THREAD_TIMEOUT", "4", 1);
        execv("/proc/self/exe", argv);
    }
    g3d_process_setup(argv);
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--reps") && i + 1 < argc) {
            g_reps = atoi(argv[++i]);
        } else if (argv[i][0] == '-' || g_filter) {
            fprintf(stderr, "usage: bench_nn [filter] [--reps N]\n");
            return 2;
        } else {
            g_filter = argv[i];
        }
    }
    if (g_reps < 1) {
        fprintf(stderr, "bench_nn: --reps needs a positive count\n");
        return 2;
    }
    g_threads = omp_get_max_threads();
    openblas_set_num_threads(g_threads);
    g_a = rnd(1536 * 1536, 1.0f), g_b = rnd(1536 * 1536, 1.0f), g_c = malloc(sizeof(float) * 1536 * 1536);
    const char *ct = getenv("OPENBLAS_CORETYPE"), *tt = getenv("OPENBLAS_THREAD_TIMEOUT");
    printf("kernels %s, %d threads, OpenBLAS core %s (OPENBLAS_CORETYPE %s%s, OPENBLAS_THREAD_TIMEOUT %s)\n",
           g3d_nn_isa_name(), g_threads, openblas_get_corename(), ct ? "= " : "unset", ct ? ct : "",
           tt ? tt : "unset");
    printf("| %-26s | %-36s | %8s | %9s | %9s | %7s | %7s | %9s |\n", "operator", "shape", "GFLOP", "ms", "cpu ms",
           "GFLOP/s", "sgemm", "sgemm cpu");
    printf("|%s|%s|%s|%s|%s|%s|%s|%s|\n", "----------------------------", "--------------------------------------",
           "----------", "-----------", "-----------", "---------", "---------", "-----------");

    lin("linear dinov2-s qkv", 1370, 384, 1152, G3D_ACT_NONE, 0, G3D_DT_F32, 0);
    lin("linear dinov2-s proj", 1370, 384, 384, G3D_ACT_NONE, 1, G3D_DT_F32, 0);
    lin("linear dinov2-s fc1", 1370, 384, 1536, G3D_ACT_GELU, 0, G3D_DT_F32, 0);
    lin("linear dinov2-s fc2", 1370, 1536, 384, G3D_ACT_NONE, 1, G3D_DT_F32, 0);
    lin("linear dinov2-s fc1 legacy", 1370, 384, 1536, G3D_ACT_NONE, 0, G3D_DT_F32, 1);
    lin("linear dinov2-l qkv", 1370, 1024, 3072, G3D_ACT_NONE, 0, G3D_DT_F32, 0);
    lin("linear dinov2-l fc1", 1370, 1024, 4096, G3D_ACT_GELU, 0, G3D_DT_F32, 0);
    lin("linear dinov2-l fc2", 1370, 4096, 1024, G3D_ACT_NONE, 1, G3D_DT_F32, 0);
    lin("linear sam-b qkv", 4096, 768, 2304, G3D_ACT_NONE, 0, G3D_DT_F32, 0);
    lin("linear sam-b mlp1", 4096, 768, 3072, G3D_ACT_GELU, 0, G3D_DT_F32, 0);
    lin("linear sam-b mlp1 bf16", 4096, 768, 3072, G3D_ACT_GELU, 0, G3D_DT_BF16, 0);
    lin("linear sam-b mlp2", 4096, 3072, 768, G3D_ACT_NONE, 1, G3D_DT_F32, 0);
    lin("linear sd geglu proj", 4096, 320, 2560, G3D_ACT_NONE, 0, G3D_DT_F32, 0);
    lin("linear sd ff out", 4096, 1280, 320, G3D_ACT_NONE, 1, G3D_DT_F32, 0);
    /* SD 1.x's cross-attention projects the 77 text tokens to its keys and values in one product
     * ([k; v] packed at load): 640 outputs at the first level (1280, 2560 deeper) */
    lin("linear sd text k/v", 77, 768, 640, G3D_ACT_NONE, 0, G3D_DT_F32, 0);

    attn("attention dinov2-s", 1370, 1370, 6, 64, 1, 0, 0);
    attn("attention dinov2-l", 1370, 1370, 16, 64, 1, 0, 0);
    attn("attention sd1 self", 4096, 4096, 8, 40, 1, 0, 0);
    attn("attention sd2 self", 4096, 4096, 5, 64, 1, 0, 0);
    attn("attention sd1 cross", 4096, 77, 8, 40, 1, 0, 0);
    attn("attention sd1 cross 32", 1024, 77, 8, 80, 1, 0, 0);
    attn("attention sd1 cross 16", 256, 77, 8, 160, 1, 0, 0);
    attn("attention sd1 self 32", 1024, 1024, 8, 80, 1, 0, 0);
    attn("attention sam-b window", 196, 196, 12, 64, 25, 1, 14);
    attn("attention sam-b global", 4096, 4096, 12, 64, 1, 1, 64);
    attn("attention vae mid", 4096, 4096, 1, 512, 1, 0, 0);

    /* 3x3: implicit GEMM (as called without preparing), then prepared (Winograd F(2x2) or F(4x4)) */
    for (int prep = 0; prep < 2; prep++) {
        const char *const names[2][11] = {
            {"conv3 sd 64x64x320", "conv3 sd 32x32x640", "conv3 sd 16x16x1280", "conv3 vae 256x256x256",
             "conv3 vae 512x512x128", "conv3 lama l2l 128", "conv3 lama g2l 384->128", "conv3 lama l2g 128->384",
             "conv3 dpt-s 64 @148", "conv3 moge 128 repl", "conv3 sd down s2"},
            {"conv3w sd 64x64x320", "conv3w sd 32x32x640", "conv3w sd 16x16x1280", "conv3w vae 256x256x256",
             "conv3w vae 512x512x128", "conv3w lama l2l 128", "conv3w lama g2l 384->128", "conv3w lama l2g 128->384",
             "conv3w dpt-s 64 @148", "conv3w moge 128 repl", NULL}};
        conv(names[prep][0], 320, 320, 3, 1, 1, 64, 64, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][1], 640, 640, 3, 1, 1, 32, 32, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][2], 1280, 1280, 3, 1, 1, 16, 16, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][3], 256, 256, 3, 1, 1, 256, 256, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][4], 128, 128, 3, 1, 1, 512, 512, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][5], 128, 128, 3, 1, 1, 64, 64, 1, G3D_PAD_REFLECT, 0, 0, prep);
        conv(names[prep][6], 384, 128, 3, 1, 1, 64, 64, 1, G3D_PAD_REFLECT, 0, 0, prep);
        conv(names[prep][7], 128, 384, 3, 1, 1, 64, 64, 1, G3D_PAD_REFLECT, 0, 0, prep);
        conv(names[prep][8], 64, 64, 3, 1, 1, 148, 148, 1, G3D_PAD_ZEROS, 0, 0, prep);
        conv(names[prep][9], 128, 128, 3, 1, 1, 160, 160, 1, G3D_PAD_REPLICATE, 0, 0, prep);
        if (names[prep][10]) conv(names[prep][10], 320, 320, 3, 2, 1, 64, 64, 1, G3D_PAD_ZEROS, 0, 0, prep);
    }
    conv("conv1 sd proj 320", 320, 320, 1, 1, 0, 64, 64, 1, G3D_PAD_ZEROS, 0, 0, 0);
    conv("conv1 lama fu 384", 384, 384, 1, 1, 0, 64, 33, 1, G3D_PAD_ZEROS, 0, 0, 0);
    conv("conv1 lama st 384->192", 384, 192, 1, 1, 0, 64, 64, 1, G3D_PAD_ZEROS, 0, 0, 0);
    conv("conv1 dpt-s 64 @148", 64, 64, 1, 1, 0, 148, 148, 1, G3D_PAD_ZEROS, 0, 0, 0);
    conv("convT lama k3s2 512->256", 512, 256, 3, 2, 1, 64, 64, 1, G3D_PAD_ZEROS, 1, 1, 1);
    conv("convT sam k2s2 256->64", 256, 64, 2, 2, 0, 64, 64, 1, G3D_PAD_ZEROS, 1, 0, 1);
    conv("convT dpt k4s4 48", 384, 48, 4, 4, 0, 37, 37, 1, G3D_PAD_ZEROS, 1, 0, 1);

    conv("dwconv 3x3 256", 256, 256, 3, 1, 1, 256, 256, 256, G3D_PAD_ZEROS, 0, 0, 0);
    misc("groupnorm+silu vae", "128 x 512x512, 32 groups", 0, 128, 512, 512);
    misc("layernorm sam-b", "4096 x 768", 1, 768, 4096, 1);
    misc("gelu sam-b mlp", "4096 x 3072", 4, 3072, 4096, 1);
    misc("rfft2 lama", "192 x 64x64", 2, 192, 64, 64);
    misc("irfft2 lama", "192 x 64x64", 3, 192, 64, 64);
    /* per kind: how many shapes, their median fraction of sgemm and the lowest; 3x3 "conv3w"
     * (Winograd) counts the direct convolution's multiply-adds, so it can exceed 100 % */
    if (!g_ran) {
        fprintf(stderr, "bench_nn: no operator's name contains \"%s\"\n", g_filter);
        return 1;
    }
    for (int memory = 0; memory < 2; memory++) {
        int any = 0;
        for (int i = 0; i < g_nkinds; i++) any |= g_kinds[i].memory == memory;
        if (!any) continue;
        if (!memory)
            printf("\nper op kind (sgemm %.0f-%.0f GFLOP/s during the run):\n", g_sgemm_lo, g_sgemm_hi);
        else
            printf("\nper memory-bound kind (streaming pass %.1f-%.1f GB/s during the run):\n", g_stream_lo, g_stream_hi);
        printf("| %-14s | %6s | %14s | %10s |\n", "kind", "shapes", memory ? "median stream" : "median sgemm", "lowest");
        printf("|----------------|--------|----------------|------------|\n");
        for (int i = 0; i < g_nkinds; i++) {
            if (g_kinds[i].memory != memory) continue;
            qsort(g_kinds[i].frac, g_kinds[i].n, sizeof(double), cmp_double);
            const int n = g_kinds[i].n;
            const double med = n % 2 ? g_kinds[i].frac[n / 2] : 0.5 * (g_kinds[i].frac[n / 2 - 1] + g_kinds[i].frac[n / 2]);
            printf("| %-14s | %6d | %12.0f %% | %8.0f %% |\n", g_kinds[i].name, n, 100.0 * med, 100.0 * g_kinds[i].frac[0]);
        }
    }
    free(g_a), free(g_b), free(g_c);
    return 0;
}
