/* testutil.h - the tiny test framework every tests/test_*.c uses.
 *
 *   TEST(name) { CHECK(cond); CHECK_NEAR(a, b, tol); CHECK_OK(g3d_call(...)); }
 *   int main(void) { RUN(name); ...; return test_summary(); }
 *
 * A failed check prints file:line and the expression, and marks the current test failed;
 * the test goes on so one run shows every failure. test_summary() prints
 * "N passed, N failed" and returns non-zero when anything failed.
 *
 * Data: test_fixture("x") is tests/fixtures/x (committed, always there); test_default_input()
 * the folder scripts/fetch-default-input.sh fills (G3D_DEFAULT_INPUT_DIR, the Middlebury frame);
 * test_shared("golden/x") a path under ../shared (G3D_SHARED_DIR), which only extended runs
 * read; test_tmp("name") a scratch path under the build folder. They return static buffers that
 * the next call of the same function overwrites (a small ring of them, so a few can be alive).
 *
 * Extended runs: a test program whose main() asks test_extended(argc, argv) is registered twice
 * by CMake, plainly and as <name>_extended (label `extended`, argument --extended). In the
 * extended run it checks only what needs ../shared; when that folder is absent the run ends at
 * once with one line saying so and exit status TEST_SKIP, which ctest reports as skipped.
 */
#ifndef G3D_TESTUTIL_H
#define G3D_TESTUTIL_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "gen3d/base.h"

static int t_failed_checks, t_tests_passed, t_tests_failed, t_extended;
static const char *t_current;

#define TEST(name) static void test_##name(void)
#define RUN(name)                                                              \
    do {                                                                       \
        int before_ = t_failed_checks;                                         \
        t_current = #name;                                                     \
        test_##name();                                                         \
        if (t_failed_checks == before_) { t_tests_passed++; printf("ok   %s\n", #name); } \
        else { t_tests_failed++; printf("FAIL %s\n", #name); }                 \
        fflush(stdout);                                                        \
    } while (0)

#define CHECK(cond)                                                                         \
    do {                                                                                    \
        if (!(cond)) {                                                                      \
            t_failed_checks++;                                                              \
            printf("  %s:%d: [%s] check failed: %s\n", __FILE__, __LINE__, t_current, #cond); \
        }                                                                                   \
    } while (0)

#define CHECK_MSG(cond, ...)                                                                \
    do {                                                                                    \
        if (!(cond)) {                                                                      \
            t_failed_checks++;                                                              \
            printf("  %s:%d: [%s] check failed: %s: ", __FILE__, __LINE__, t_current, #cond); \
            printf(__VA_ARGS__);                                                            \
            printf("\n");                                                                   \
        }                                                                                   \
    } while (0)

#define CHECK_NEAR(a, b, tol)                                                               \
    do {                                                                                    \
        double a_ = (double)(a), b_ = (double)(b);                                          \
        if (!(fabs(a_ - b_) <= (tol))) {                                                    \
            t_failed_checks++;                                                              \
            printf("  %s:%d: [%s] %s = %.9g, expected %s = %.9g (tol %g)\n", __FILE__,       \
                   __LINE__, t_current, #a, a_, #b, b_, (double)(tol));                     \
        }                                                                                   \
    } while (0)

/* Expects G3D_OK; prints the library's message otherwise. */
#define CHECK_OK(expr)                                                                      \
    do {                                                                                    \
        g3d_status s_ = (expr);                                                             \
        if (s_ != G3D_OK) {                                                                 \
            t_failed_checks++;                                                              \
            printf("  %s:%d: [%s] %s failed: %s\n", __FILE__, __LINE__, t_current, #expr,    \
                   g3d_error_message());                                                    \
        }                                                                                   \
    } while (0)

/* Expects a failure status and a non-empty message; prints the message (-v style) so the
 * log shows what users would read. */
#define CHECK_FAILS(expr)                                                                   \
    do {                                                                                    \
        g3d_error_clear();                                                                  \
        g3d_status s_ = (expr);                                                             \
        if (s_ == G3D_OK || !g3d_error_message()[0]) {                                      \
            t_failed_checks++;                                                              \
            printf("  %s:%d: [%s] expected %s to fail with a message\n", __FILE__, __LINE__, \
                   t_current, #expr);                                                       \
        } else {                                                                            \
            printf("       rejected as expected: %s\n", g3d_error_message());               \
        }                                                                                   \
    } while (0)

static inline int test_summary(void)
{
    printf("%d passed, %d failed\n", t_tests_passed, t_tests_failed);
    return t_tests_failed ? 1 : 0;
}

#define TEST_SKIP 77   /* ctest's SKIP_RETURN_CODE for the extended runs */

/* Non-zero in the extended run (argument --extended); exits with TEST_SKIP when it has no
 * shared folder. */
static inline int test_extended(int argc, char **argv)
{
    struct stat st;
    if (argc < 2 || strcmp(argv[1], "--extended")) return 0;
    if (stat(G3D_SHARED_DIR, &st) != 0 || !S_ISDIR(st.st_mode)) {
        printf("skipped: no shared reference data at %s (configure with -DG3D_SHARED_DIR=DIR)\n", G3D_SHARED_DIR);
        exit(TEST_SKIP);
    }
    return t_extended = 1;
}

static inline const char *test_fixture(const char *name)
{
    static char buf[8][1024];
    static int k;
    char *b = buf[k++ & 7];
    snprintf(b, 1024, "%s/tests/fixtures/%s", G3D_SOURCE_DIR, name);
    return b;
}

/* The default input's folder; a failed check with the remedy when its files are not there. */
static inline const char *test_default_input(void)
{
    struct stat st;
    char p[1024];
    snprintf(p, sizeof p, "%s/motorcycle_disp.npz", G3D_DEFAULT_INPUT_DIR);
    CHECK_MSG(stat(p, &st) == 0, "no default input in %s: run scripts/fetch-default-input.sh", G3D_DEFAULT_INPUT_DIR);
    return G3D_DEFAULT_INPUT_DIR;
}

/* A path under the shared folder; a failed check outside the extended run, which alone may
 * read it (a clone has no such folder). */
static inline const char *test_shared(const char *rel)
{
    static char buf[8][1024];
    static int k;
    char *b = buf[k++ & 7];
    CHECK_MSG(t_extended, "%s: shared data read outside the extended run", rel);
    snprintf(b, 1024, "%s/%s", G3D_SHARED_DIR, rel);
    return b;
}

static inline const char *test_tmp(const char *name)
{
    static char buf[8][1024];
    static int k;
    char *b = buf[k++ & 7];
    mkdir(G3D_TEST_TMP, 0755);
    snprintf(b, 1024, "%s/%s", G3D_TEST_TMP, name);
    return b;
}

static inline int test_file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* ||a - b|| / ||b|| over n floats (0 when both are zero). */
static inline double test_rel_l2(const float *a, const float *b, size_t n)
{
    double num = 0, den = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a[i] - (double)b[i];
        num += d * d;
        den += (double)b[i] * (double)b[i];
    }
    return den > 0 ? sqrt(num / den) : sqrt(num);
}

#endif /* G3D_TESTUTIL_H */
