/* PCG32 (O'Neill): small state, good statistics, reproducible across platforms. */
#include "gen3d/base.h"

#include <math.h>

void g3d_rng_seed(g3d_rng *r, uint64_t seed, uint64_t stream)
{
    r->state = 0;
    r->inc = (stream << 1u) | 1u;
    g3d_rng_u32(r);
    r->state += seed;
    g3d_rng_u32(r);
}

uint32_t g3d_rng_u32(g3d_rng *r)
{
    uint64_t old = r->state;
    uint32_t xorshifted, rot;
    r->state = old * 6364136223846793005ULL + r->inc;
    xorshifted = (uint32_t)(((old >> 18u) ^ old) >> 27u);
    rot = (uint32_t)(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((-rot) & 31));
}

float g3d_rng_float(g3d_rng *r) { return (float)(g3d_rng_u32(r) >> 8) * (1.0f / 16777216.0f); }

uint32_t g3d_rng_below(g3d_rng *r, uint32_t n)
{
    uint32_t threshold = (0u - n) % n;
    for (;;) {
        uint32_t x = g3d_rng_u32(r);
        if (x >= threshold) return x % n;
    }
}

float g3d_rng_normal(g3d_rng *r)
{
    float u1 = g3d_rng_float(r), u2 = g3d_rng_float(r);
    if (u1 < 1e-12f) u1 = 1e-12f;
    return sqrtf(-2.0f * logf(u1)) * cosf(6.283185307179586f * u2);
}
