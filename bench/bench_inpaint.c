/* Times the exemplar inpainter against the diffusion fill on the same inputs: a textured
 * synthetic image with a border band hole (the usual world-generation case) covering 10 % or
 * 30 % of the width, at 256^2, 512^2 and 1024^2. Prints seconds and the ratio. */
#include "gen3d/inpaint_classic.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void texture(g3d_image *im, uint64_t seed)
{
    g3d_rng rng;
    g3d_rng_seed(&rng, seed, 0);
    for (int y = 0; y < im->h; y++)
        for (int x = 0; x < im->w; x++) {
            float *v = g3d_image_px(im, x, y);
            float a = 0.5f + 0.25f * sinf(0.21f * (float)x + 0.13f * (float)y) + 0.1f * g3d_rng_float(&rng);
            v[0] = a;
            v[1] = 0.6f * a + 0.1f * ((x / 12 + y / 12) % 2);
            v[2] = 1.f - a;
        }
}

int main(void)
{
    const int sides[3] = {256, 512, 1024};
    const int pcts[2] = {10, 30};
    printf("%-10s %5s %12s %12s %8s\n", "size", "hole", "patchmatch_s", "diffusion_s", "ratio");
    for (int si = 0; si < 3; si++)
        for (int pi = 0; pi < 2; pi++) {
            int n = sides[si];
            g3d_image base, a, b, m;
            if (g3d_image_create(&base, n, n, 3) || g3d_image_create(&m, n, n, 1)) return 1;
            texture(&base, 1);
            int band = n * pcts[pi] / 100;
            for (int y = 0; y < n; y++)
                for (int x = n - band; x < n; x++) m.data[(size_t)y * n + x] = 1.f;
            if (g3d_image_clone(&a, &base) || g3d_image_clone(&b, &base)) return 1;
            double t0 = now();
            if (g3d_inpaint_patchmatch(&a, &m, NULL, 1)) {
                fprintf(stderr, "%s\n", g3d_error_message());
                return 1;
            }
            double t1 = now();
            if (g3d_inpaint_diffusion(&b, &m)) return 1;
            double t2 = now();
            printf("%4dx%-5d %4d%% %12.3f %12.3f %8.1f\n", n, n, pcts[pi], t1 - t0, t2 - t1, (t1 - t0) / (t2 - t1));
            fflush(stdout);
            g3d_image_free(&base);
            g3d_image_free(&a);
            g3d_image_free(&b);
            g3d_image_free(&m);
        }
    return 0;
}
