/* Sorting and medians of float arrays, shared by the statistics of several stages. */
#include "gen3d/base.h"

#include <stdlib.h>

static int cmp_f32(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

void g3d_sort_f32(float *v, size_t n) { qsort(v, n, sizeof *v, cmp_f32); }

float g3d_median_f32(float *v, size_t n)
{
    g3d_sort_f32(v, n);
    return n % 2 ? v[n / 2] : 0.5f * (v[n / 2 - 1] + v[n / 2]);
}
