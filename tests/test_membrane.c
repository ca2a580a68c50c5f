/* Harmonic interpolation: exact on fields it must reproduce, smooth, keeps known values. */
#include "testutil.h"
#include "gen3d/membrane.h"

TEST(reproduces_linear_fields)
{
    /* A linear field is harmonic: with a ring of known values around a hole it is recovered. */
    int w = 120, h = 90;
    float *v = malloc(sizeof(float) * w * h), *truth = malloc(sizeof(float) * w * h);
    uint8_t *known = malloc((size_t)w * h);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            truth[i] = 0.3f + 0.01f * x - 0.02f * y;
            int hole = (x - 60) * (x - 60) + (y - 45) * (y - 45) < 30 * 30;
            known[i] = !hole;
            v[i] = hole ? 1234.0f : truth[i];
        }
    CHECK_OK(g3d_membrane_fill(v, known, w, h));
    double worst = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) worst = fmax(worst, fabs(v[i] - truth[i]));
    printf("  linear field through a 60 px hole: max error %.2e\n", worst);
    CHECK(worst < 2e-3);
    free(v); free(truth); free(known);
}

TEST(border_hole_and_bounds)
{
    /* Known values on the left half only: the field continues flat to the right border and
     * stays within the range of the known values (maximum principle). */
    int w = 64, h = 48;
    float *v = malloc(sizeof(float) * w * h);
    uint8_t *known = malloc((size_t)w * h);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            known[i] = x < 32;
            v[i] = known[i] ? (float)(1.0 + 0.5 * sin(y * 0.2)) : NAN;
        }
    for (size_t i = 0; i < (size_t)w * h; i++) if (!known[i]) v[i] = 0;
    CHECK_OK(g3d_membrane_fill(v, known, w, h));
    double lo = 1e9, hi = -1e9, row_dev = 0;
    for (int y = 0; y < h; y++)
        for (int x = 32; x < w; x++) {
            float a = v[(size_t)y * w + x];
            lo = fmin(lo, a);
            hi = fmax(hi, a);
        }
    /* Far from the known band, each row is nearly constant (flat continuation). */
    for (int y = 0; y < h; y++) row_dev = fmax(row_dev, fabs(v[(size_t)y * w + w - 1] - v[(size_t)y * w + w - 2]));
    CHECK(lo >= 0.5 - 1e-4 && hi <= 1.5 + 1e-4);
    CHECK(row_dev < 0.01);
    for (int y = 0; y < h; y++) CHECK(v[(size_t)y * w] == (float)(1.0 + 0.5 * sin(y * 0.2)));
    memset(known, 0, (size_t)w * h);
    CHECK_FAILS(g3d_membrane_fill(v, known, w, h));
    free(v); free(known);
}

int main(void)
{
    RUN(reproduces_linear_fields);
    RUN(border_hole_and_bounds);
    return test_summary();
}
