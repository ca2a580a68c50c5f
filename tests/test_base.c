/* Base module: errors, checked sizes, RNG determinism, atomic files and folders. */
#include "testutil.h"
#include "gen3d/base.h"
#include "gen3d/image.h"

#include <stdint.h>
#include <unistd.h>

TEST(error_messages)
{
    g3d_status rc = G3D_ERR(G3D_ERR_FORMAT, "%s: truncated", "x.png");
    CHECK(rc == G3D_ERR_FORMAT);
    CHECK(strstr(g3d_error_message(), "x.png: truncated") == g3d_error_message());
    g3d_error_prefix("loading");
    CHECK(!strncmp(g3d_error_message(), "loading: x.png", 14));
    CHECK(!strcmp(g3d_status_name(G3D_ERR_IO), "io"));
}

TEST(size_overflow)
{
    size_t out = 7;
    CHECK(g3d_size_mul(1u << 20, 1u << 20, &out) && out == (size_t)1 << 40);
    out = 7;
    CHECK(!g3d_size_mul(SIZE_MAX / 2, 3, &out) && out == 7);
    CHECK(!g3d_size_mul3(1u << 30, 1u << 30, 1u << 30, &out));
    CHECK(g3d_calloc(SIZE_MAX / 4, 8, "huge") == NULL);
    CHECK(strstr(g3d_error_message(), "huge") != NULL);
    g3d_image img;
    CHECK_FAILS(g3d_image_create(&img, 40000, 10, 3));
    CHECK_FAILS(g3d_image_create(&img, 0, 10, 3));
}

TEST(rng_deterministic)
{
    g3d_rng a, b, c;
    g3d_rng_seed(&a, 42, 1);
    g3d_rng_seed(&b, 42, 1);
    g3d_rng_seed(&c, 43, 1);
    int same_ab = 1, same_ac = 1;
    double mean = 0, var = 0;
    for (int i = 0; i < 10000; i++) {
        uint32_t x = g3d_rng_u32(&a), y = g3d_rng_u32(&b), z = g3d_rng_u32(&c);
        same_ab &= x == y;
        same_ac &= x == z;
        float f = g3d_rng_float(&a);
        g3d_rng_float(&b);
        g3d_rng_float(&c);
        CHECK(f >= 0.0f && f < 1.0f);
        float n = g3d_rng_normal(&a);
        g3d_rng_normal(&b);
        g3d_rng_normal(&c);
        mean += n;
        var += n * n;
    }
    CHECK(same_ab);
    CHECK(!same_ac);
    CHECK_NEAR(mean / 10000, 0.0, 0.05);
    CHECK_NEAR(var / 10000, 1.0, 0.05);
    for (int i = 0; i < 1000; i++) CHECK(g3d_rng_below(&a, 7) < 7);
}

TEST(atomic_file)
{
    const char *path = test_tmp("atomic.txt");
    g3d_atomic_file af;
    remove(path);
    CHECK_OK(g3d_atomic_open(&af, path));
    fputs("hello", af.fp);
    CHECK(!test_file_exists(path)); /* nothing under the final name before commit */
    CHECK_OK(g3d_atomic_commit(&af));
    unsigned char *data = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(path, 1 << 20, &data, &n));
    CHECK(n == 5 && data && !memcmp(data, "hello", 5));
    free(data);

    /* An abandoned write leaves the old content and no temporary file. */
    CHECK_OK(g3d_atomic_open(&af, path));
    char tmp[1024];
    snprintf(tmp, sizeof tmp, "%s", af.tmp_path);
    fputs("partial", af.fp);
    g3d_atomic_abort(&af);
    CHECK(!test_file_exists(tmp));
    CHECK_OK(g3d_read_file(path, 1 << 20, &data, &n));
    CHECK(n == 5);
    free(data);

    CHECK_FAILS(g3d_atomic_open(&af, "/nonexistent-dir/x.txt"));
    CHECK_FAILS(g3d_read_file("/nonexistent-dir/x.txt", 100, &data, &n));
    CHECK_FAILS(g3d_read_file(path, 2, &data, &n)); /* over the size limit */
}

TEST(atomic_dir)
{
    const char *path = test_tmp("atomic_dir");
    char *tmp = NULL;
    g3d_remove_tree(path);
    CHECK_OK(g3d_atomic_dir_begin(path, &tmp));
    char *f = g3d_path_join(tmp, "a.txt");
    CHECK_OK(g3d_write_file_atomic(f, "x", 1));
    free(f);
    CHECK(!test_file_exists(path));
    CHECK_OK(g3d_atomic_dir_commit(tmp, path));
    f = g3d_path_join(path, "a.txt");
    CHECK(test_file_exists(f));
    free(f);
    free(tmp);

    /* A folder of the user's that is not empty and not ours is never replaced. */
    char *mine = g3d_path_join(test_tmp(""), "users_folder");
    g3d_remove_tree(mine);
    g3d_mkdirs(mine);
    char *keep = g3d_path_join(mine, "precious.txt");
    g3d_write_file_atomic(keep, "x", 1);
    CHECK_OK(g3d_atomic_dir_begin(mine, &tmp));
    CHECK_FAILS(g3d_atomic_dir_commit(tmp, mine));
    CHECK(test_file_exists(keep));
    g3d_atomic_dir_abort(tmp);
    free(tmp);
    free(keep);
    g3d_remove_tree(mine);
    free(mine);
    /* Our own earlier output is replaced. */
    CHECK_OK(g3d_atomic_dir_begin(path, &tmp));
    CHECK_OK(g3d_atomic_dir_commit(tmp, path));
    free(tmp);

    CHECK_OK(g3d_atomic_dir_begin(path, &tmp));
    g3d_atomic_dir_abort(tmp);
    CHECK(!test_file_exists(tmp));
    free(tmp);
    char ext[8];
    CHECK(!strcmp(g3d_path_ext("a/b.c/d.PNG", ext, sizeof ext), "png"));
    CHECK(!strcmp(g3d_path_ext("a/b.c/d", ext, sizeof ext), ""));
}

int main(void)
{
    RUN(error_messages);
    RUN(size_overflow);
    RUN(rng_deterministic);
    RUN(atomic_file);
    RUN(atomic_dir);
    return test_summary();
}
