/* Gaussian model storage: create, grow, compact, clone, validation. */
#include "testutil.h"
#include "gen3d/gaussians.h"

TEST(storage)
{
    g3d_gaussians g, c;
    CHECK_OK(g3d_gaussians_create(&g, 2, 3));
    for (int i = 0; i < 5; i++) {
        CHECK_OK(g3d_gaussians_reserve(&g, g.n + 1));
        g.means[3 * g.n] = (float)i;
        g.sh[g.n * 48 + 47] = (float)(10 * i);
        g.opacity_logits[g.n] = (float)-i;
        g.n++;
    }
    CHECK(g.n == 5 && g.capacity >= 5);
    CHECK(g.means[3 * 4] == 4.0f && g.sh[4 * 48 + 47] == 40.0f);
    uint8_t keep[5] = {1, 0, 1, 0, 1};
    CHECK(g3d_gaussians_compact(&g, keep) == 3);
    CHECK(g.means[3 * 1] == 2.0f && g.opacity_logits[2] == -4.0f && g.sh[2 * 48 + 47] == 40.0f);
    CHECK_OK(g3d_gaussians_clone(&c, &g));
    CHECK(c.n == 3 && c.sh[2 * 48 + 47] == 40.0f);
    CHECK_OK(g3d_gaussians_validate(&c, "clone"));
    c.rots[4 * 1 + 2] = NAN;
    CHECK_FAILS(g3d_gaussians_validate(&c, "clone"));
    CHECK(strstr(g3d_error_message(), "Gaussian 1") != NULL);
    g3d_gaussians_free(&c);
    CHECK_FAILS(g3d_gaussians_create(&c, 1, 4));
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&c);
    g3d_gaussians_free(NULL);
}

int main(void)
{
    RUN(storage);
    return test_summary();
}
