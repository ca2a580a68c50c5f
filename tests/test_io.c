/* Image, depth and archive files: bit-exact round trips and hostile inputs. */
#include "testutil.h"
#include "gen3d/depthio.h"
#include "gen3d/frame.h"
#include "gen3d/imageio.h"
#include "gen3d/npy.h"
#include "gen3d/zip.h"

#include <zlib.h>

static void write_bytes(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    if (n) fwrite(data, 1, n, f);
    fclose(f);
}

static unsigned char *slurp(const char *path, size_t *n)
{
    unsigned char *d = NULL;
    g3d_read_file(path, (size_t)1 << 30, &d, n);
    return d;
}

static void fill_pattern(g3d_image *img, int levels)
{
    for (size_t i = 0; i < g3d_image_size(img); i++) img->data[i] = (float)((i * 7919u) % (unsigned)levels) / (float)(levels - 1);
}

TEST(png_round_trip_8_and_16_bit)
{
    for (int bits = 8; bits <= 16; bits += 8) {
        for (int c = 1; c <= 3; c += 2) {
            g3d_image a, b;
            CHECK_OK(g3d_image_create(&a, 37, 23, c));
            fill_pattern(&a, bits == 8 ? 256 : 65536);
            const char *p = test_tmp("rt.png");
            CHECK_OK(g3d_image_save_png(p, &a, bits));
            CHECK_OK(g3d_image_load(p, c, &b));
            CHECK(b.w == 37 && b.h == 23 && b.c == c);
            int exact = 1;
            for (size_t i = 0; i < g3d_image_size(&a); i++) exact &= a.data[i] == b.data[i];
            CHECK_MSG(exact, "%d-bit, %d channels", bits, c);
            g3d_image_free(&a);
            g3d_image_free(&b);
        }
    }
    /* Raw 16-bit values survive exactly, and 8-bit files are refused as depth. */
    g3d_image d, r;
    CHECK_OK(g3d_image_create(&d, 5, 4, 1));
    for (int i = 0; i < 20; i++) d.data[i] = (float)(i * 3000);
    CHECK_OK(g3d_image_save_png_u16(test_tmp("u16.png"), &d));
    CHECK_OK(g3d_image_load_u16(test_tmp("u16.png"), &r));
    for (int i = 0; i < 20; i++) CHECK(r.data[i] == d.data[i]);
    g3d_image_free(&r);
    CHECK_OK(g3d_image_save_png(test_tmp("u8.png"), &d, 8));
    CHECK_FAILS(g3d_image_load_u16(test_tmp("u8.png"), &r));
    g3d_image_free(&d);
}

TEST(depth_round_trips)
{
    g3d_image d, back;
    CHECK_OK(g3d_image_create(&d, 31, 17, 1));
    for (size_t i = 0; i < g3d_image_size(&d); i++) d.data[i] = 0.5f + 0.0137f * (float)i;
    d.data[3] = 0;
    const char *ext[] = {"pfm", "npy"};
    for (int k = 0; k < 2; k++) {
        char name[32];
        snprintf(name, sizeof name, "depth.%s", ext[k]);
        CHECK_OK(g3d_depth_save(test_tmp(name), &d));
        CHECK_OK(g3d_depth_load(test_tmp(name), 0, &back));
        CHECK(back.w == d.w && back.h == d.h);
        CHECK_MSG(!memcmp(back.data, d.data, g3d_image_size(&d) * sizeof(float)), "%s not bit-identical", ext[k]);
        g3d_image_free(&back);
    }
    /* 16-bit PNG in millimetres: exact to the millimetre. */
    CHECK_OK(g3d_depth_save(test_tmp("depth.png"), &d));
    CHECK_OK(g3d_depth_load(test_tmp("depth.png"), 1000, &back));
    double worst = 0;
    for (size_t i = 0; i < g3d_image_size(&d); i++) worst = fmax(worst, fabs(back.data[i] - d.data[i]));
    CHECK(worst <= 0.0005 + 1e-6);
    g3d_image_free(&back);
    /* Big-endian PFM (positive scale) with rows stored bottom-to-top; inf and negative
     * values become invalid (0) through g3d_depth_load but survive g3d_pfm_load. */
    const unsigned char be_pfm[] = "Pf\n2 2\n1.0\n"
                                   "\x3f\x80\x00\x00" "\x40\x00\x00\x00"  /* bottom row: 1, 2 */
                                   "\x7f\x80\x00\x00" "\xc0\x40\x00\x00"; /* top row: inf, -3 */
    write_bytes(test_tmp("be.pfm"), be_pfm, sizeof be_pfm - 1);
    CHECK_OK(g3d_pfm_load(test_tmp("be.pfm"), &back));
    CHECK(back.w == 2 && back.h == 2 && isinf(back.data[0]) && back.data[1] == -3.0f);
    CHECK(back.data[2] == 1.0f && back.data[3] == 2.0f);
    g3d_image_free(&back);
    CHECK_OK(g3d_depth_load(test_tmp("be.pfm"), 0, &back));
    CHECK(back.data[0] == 0 && back.data[1] == 0 && back.data[2] == 1.0f && back.data[3] == 2.0f);
    g3d_image_free(&back);
    /* TUM scale 5000. */
    CHECK_OK(g3d_depth_load(test_tmp("depth.png"), 5000, &back));
    CHECK_NEAR(back.data[10], d.data[10] / 5.0, 0.0002);
    g3d_image_free(&back);
    g3d_image_free(&d);
}

/* The Middlebury disparity (fetched with the default input): 741 x 500 float32 with inf where
 * there is no ground truth. */
TEST(npz_default_input)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/motorcycle_disp.npz", test_default_input());
    g3d_array a;
    CHECK_OK(g3d_npz_load(path, NULL, &a));
    CHECK(a.data && a.ndim == 2 && a.shape[0] == 500 && a.shape[1] == 741);
    if (a.data && a.ndim == 2 && a.shape[0] == 500 && a.shape[1] == 741) {
        size_t inf = 0, n = (size_t)741 * 500;
        for (size_t i = 0; i < n; i++) inf += isinf(a.data[i]);
        CHECK_NEAR((double)inf / n, 0.074, 0.005); /* 7.4 % without ground truth */
    }
    g3d_array_free(&a);
    CHECK_FAILS(g3d_npz_load(path, "nope", &a));
}

TEST(npz_and_real_pfm)
{
    /* The shared Middlebury disparity exists both as NPZ and PFM: they must agree exactly. */
    g3d_array a;
    g3d_image pfm;
    CHECK_OK(g3d_npz_load(test_shared("testdata/middlebury2014_motorcycle_skimage/motorcycle_disp.npz"), NULL, &a));
    CHECK_OK(g3d_pfm_load(test_shared("testdata/middlebury2014_motorcycle_skimage/disp0.pfm"), &pfm));
    CHECK(a.ndim == 2 && a.shape[0] == 500 && a.shape[1] == 741);
    CHECK(pfm.w == 741 && pfm.h == 500);
    if (a.data && pfm.data && a.ndim == 2 && a.shape[0] == 500 && a.shape[1] == 741 && pfm.w == 741 && pfm.h == 500) {
        size_t same = 0, inf = 0, n = (size_t)741 * 500;
        for (size_t i = 0; i < n; i++) {
            same += a.data[i] == pfm.data[i] || (isinf(a.data[i]) && isinf(pfm.data[i]));
            inf += isinf(a.data[i]);
        }
        CHECK(same == n);
        CHECK_NEAR((double)inf / n, 0.074, 0.005); /* the README's 7.4 % without ground truth */
    }
    g3d_array_free(&a);
    CHECK_FAILS(g3d_npz_load(test_shared("testdata/middlebury2014_motorcycle_skimage/motorcycle_disp.npz"), "nope", &a));
    g3d_image_free(&pfm);
}

/* NPY float16 and big-endian float32, as numpy writes them. */
TEST(npy_dtypes)
{
    g3d_array a;
    unsigned char npy[128] = "\x93NUMPY\x01\x00";
    const char *hdr = "{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }";
    size_t hl = strlen(hdr);
    npy[8] = (unsigned char)hl;
    memcpy(npy + 10, hdr, hl);
    unsigned char be[8] = {0x3f, 0x80, 0, 0, 0xc0, 0x00, 0, 0}; /* 1.0, -2.0 */
    memcpy(npy + 10 + hl, be, 8);
    CHECK_OK(g3d_npy_parse(npy, 10 + hl + 8, "be.npy", &a));
    CHECK(a.data && a.data[0] == 1.0f && a.data[1] == -2.0f);
    g3d_array_free(&a);
    hdr = "{'descr': '<f2', 'fortran_order': False, 'shape': (2,), }";
    memcpy(npy + 10, hdr, hl);
    unsigned char h[4] = {0x00, 0x3c, 0x01, 0x00}; /* 1.0, smallest subnormal */
    memcpy(npy + 10 + hl, h, 4);
    CHECK_OK(g3d_npy_parse(npy, 10 + hl + 4, "f16.npy", &a));
    CHECK(a.data && a.data[0] == 1.0f && a.data[1] == ldexpf(1.0f, -24));
    g3d_array_free(&a);
}

TEST(hostile_files)
{
    g3d_image img;
    g3d_array a;
    size_t n;
    const char *p = test_tmp("bad.bin");

    /* 1. empty file as an image */
    write_bytes(p, "", 0);
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    /* 2. missing file */
    CHECK_FAILS(g3d_image_load(test_tmp("does-not-exist.png"), 3, &img));
    /* 3. truncated PNG */
    g3d_image ok;
    g3d_image_create(&ok, 64, 64, 3);
    fill_pattern(&ok, 256);
    g3d_image_save_png(test_tmp("good.png"), &ok, 8);
    g3d_image_free(&ok);
    unsigned char *good = slurp(test_tmp("good.png"), &n);
    write_bytes(p, good, n / 2);
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    /* 4. PNG header claiming a 40000-pixel side */
    unsigned char big[64];
    memcpy(big, good, n < 64 ? n : 64);
    big[16] = 0; big[17] = 0; big[18] = 0x9c; big[19] = 0x40; /* width 40000 */
    uLong crc = crc32(0, big + 12, 17);
    big[29] = (unsigned char)(crc >> 24); big[30] = (unsigned char)(crc >> 16); big[31] = (unsigned char)(crc >> 8); big[32] = (unsigned char)crc;
    write_bytes(p, big, 64);
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    free(good);
    /* 5. text file with a .png name */
    write_bytes(test_tmp("text.png"), "hello, world", 12);
    CHECK_FAILS(g3d_image_load(test_tmp("text.png"), 3, &img));
    /* 6. PFM with a bad header */
    write_bytes(test_tmp("bad.pfm"), "P7\n4 4\n-1\n", 10);
    CHECK_FAILS(g3d_depth_load(test_tmp("bad.pfm"), 0, &img));
    /* 7. PFM with truncated data */
    write_bytes(test_tmp("short.pfm"), "Pf\n4 4\n-1\n0123456789", 20);
    CHECK_FAILS(g3d_depth_load(test_tmp("short.pfm"), 0, &img));
    /* 8. PFM with an absurd size */
    write_bytes(test_tmp("huge.pfm"), "Pf\n100000 4\n-1\n", 16);
    CHECK_FAILS(g3d_depth_load(test_tmp("huge.pfm"), 0, &img));
    /* 9. three-channel PFM used as depth */
    float px[3] = {1, 2, 3};
    FILE *f = fopen(test_tmp("rgb.pfm"), "wb");
    fprintf(f, "PF\n1 1\n-1\n");
    fwrite(px, 4, 3, f);
    fclose(f);
    CHECK_FAILS(g3d_depth_load(test_tmp("rgb.pfm"), 0, &img));
    /* 10-14. NPY: bad magic, unsupported dtype, Fortran order, truncated data, malformed shape */
    const char *hdrs[] = {
        "{'descr': '<i8', 'fortran_order': False, 'shape': (2, 2), }",
        "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (200, 200), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (2, x), }",
    };
    CHECK_FAILS(g3d_npy_parse((const unsigned char *)"NOTNUMPY....", 12, "magic.npy", &a));
    for (int i = 0; i < 4; i++) {
        unsigned char buf[256] = "\x93NUMPY\x01\x00";
        size_t hl = strlen(hdrs[i]);
        buf[8] = (unsigned char)hl;
        memcpy(buf + 10, hdrs[i], hl);
        CHECK_FAILS(g3d_npy_parse(buf, 10 + hl + 16, "case.npy", &a));
    }
    /* 15. NPY header length past the end */
    unsigned char trunc[12] = "\x93NUMPY\x01\x00\xff\x00";
    CHECK_FAILS(g3d_npy_parse(trunc, 12, "trunc.npy", &a));
    /* 16. NPZ that is not a zip */
    write_bytes(test_tmp("bad.npz"), "not a zip at all, really", 24);
    CHECK_FAILS(g3d_depth_load(test_tmp("bad.npz"), 0, &img));
    /* 17. unknown depth extension */
    CHECK_FAILS(g3d_depth_load(test_tmp("depth.tiff"), 0, &img));
    /* 18. RGB and depth of different sizes */
    g3d_image rgb, dep;
    g3d_image_create(&rgb, 20, 10, 3);
    g3d_image_create(&dep, 21, 10, 1);
    for (int i = 0; i < 210; i++) dep.data[i] = 1.0f;
    g3d_image_save_png(test_tmp("rgb20.png"), &rgb, 8);
    g3d_depth_save(test_tmp("dep21.npy"), &dep);
    g3d_frame fr;
    g3d_intrinsics K = {0};
    CHECK_FAILS(g3d_frame_load_rgbd(test_tmp("rgb20.png"), test_tmp("dep21.npy"), 0, K, 0, &fr));
    /* 19. all-invalid (NaN) depth */
    g3d_image_free(&dep);
    g3d_image_create(&dep, 20, 10, 1);
    for (int i = 0; i < 200; i++) dep.data[i] = NAN;
    int64_t shape[2] = {10, 20};
    g3d_npy_save(test_tmp("nan.npy"), dep.data, 2, shape);
    CHECK_FAILS(g3d_frame_load_rgbd(test_tmp("rgb20.png"), test_tmp("nan.npy"), 0, K, 0, &fr));
    /* 20. a 3-D array used as depth */
    int64_t s3[3] = {2, 10, 10};
    g3d_npy_save(test_tmp("rank3.npy"), dep.data, 3, s3);
    CHECK_FAILS(g3d_depth_load(test_tmp("rank3.npy"), 0, &img));
    /* 21. Middlebury folder without the files */
    CHECK_FAILS(g3d_frame_load_middlebury(test_tmp("no-such-folder"), &fr));
    g3d_image_free(&rgb);
    g3d_image_free(&dep);
    (void)a;
}

/* JPEG files decode to the pixels PIL (and OpenCV) decode: 4:2:0 and 4:2:2 chroma at odd
 * sizes, progressive, grey (tests/fixtures/make_jpeg_fixture.py). */
TEST(jpeg_pixels_as_pil)
{
    static const char *names[] = {"jpeg_420_61x47", "jpeg_422p_45x31", "jpeg_grey_23x17"};
    for (int k = 0; k < 3; k++) {
        char jpg[64], png[64];
        snprintf(jpg, sizeof jpg, "%s.jpg", names[k]);
        snprintf(png, sizeof png, "%s.png", names[k]);
        g3d_image a = {0}, b = {0};
        CHECK_OK(g3d_image_load(test_fixture(jpg), 0, &a));
        CHECK_OK(g3d_image_load(test_fixture(png), 0, &b));
        CHECK(a.data && b.data && a.w == b.w && a.h == b.h && a.c == b.c && a.c == (k == 2 ? 1 : 3));
        if (a.data && b.data && a.w == b.w && a.h == b.h && a.c == b.c) {
            size_t differ = 0;
            for (size_t i = 0; i < g3d_image_size(&a); i++) differ += a.data[i] != b.data[i];
            printf("  %s: %dx%dx%d, %zu samples differ from PIL's\n", jpg, a.w, a.h, a.c, differ);
            CHECK(differ == 0);
        }
        g3d_image_free(&a);
        g3d_image_free(&b);
    }
    /* a grey file read as RGB repeats the grey value */
    g3d_image g = {0}, rgb = {0};
    CHECK_OK(g3d_image_load(test_fixture("jpeg_grey_23x17.jpg"), 1, &g));
    CHECK_OK(g3d_image_load(test_fixture("jpeg_grey_23x17.jpg"), 3, &rgb));
    int same = g.data && rgb.data && rgb.c == 3;
    for (size_t i = 0; same && i < (size_t)g.w * g.h; i++)
        same = rgb.data[3 * i] == g.data[i] && rgb.data[3 * i + 1] == g.data[i] && rgb.data[3 * i + 2] == g.data[i];
    CHECK(same);
    g3d_image_free(&g);
    g3d_image_free(&rgb);
}

/* Broken JPEG files: each refused with a message naming the file, nothing returned. */
TEST(hostile_jpeg)
{
    size_t n = 0;
    unsigned char *good = slurp(test_fixture("jpeg_420_61x47.jpg"), &n);
    CHECK(good && n > 600);
    if (!good || n <= 600) {
        free(good);
        return;
    }
    const char *p = test_tmp("bad.jpg");
    g3d_image img = {0};
    write_bytes(p, good, n - 300); /* truncated in the entropy-coded data */
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    CHECK(img.data == NULL && strstr(g3d_error_message(), "bad.jpg"));
    write_bytes(p, good, 200); /* truncated in the headers */
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    static const char not_jpeg[] = "\xff\xd8\xff\xe0 not a JPEG at all";
    write_bytes(p, not_jpeg, sizeof not_jpeg - 1);
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    /* a frame header claiming a 40000-pixel width */
    for (size_t i = 0; i + 9 < n; i++)
        if (good[i] == 0xFF && good[i + 1] == 0xC0) {
            good[i + 7] = 0x9c;
            good[i + 8] = 0x40;
            break;
        }
    write_bytes(p, good, n);
    CHECK_FAILS(g3d_image_load(p, 3, &img));
    CHECK(img.data == NULL && strstr(g3d_error_message(), "40000"));
    free(good);
    /* CMYK (Adobe) JPEG: PIL converts it by its own rules; not supported here */
    CHECK_FAILS(g3d_image_load(test_fixture("jpeg_cmyk_8x8.jpg"), 3, &img));
    CHECK(strstr(g3d_error_message(), "CMYK") != NULL);
    /* a JPEG is not a 16-bit depth PNG */
    CHECK_FAILS(g3d_image_load_u16(test_fixture("jpeg_grey_23x17.jpg"), &img));
}

int main(int argc, char **argv)
{
    if (test_extended(argc, argv)) {
        RUN(npz_and_real_pfm);
        return test_summary();
    }
    RUN(png_round_trip_8_and_16_bit);
    RUN(depth_round_trips);
    RUN(npz_default_input);
    RUN(npy_dtypes);
    RUN(jpeg_pixels_as_pil);
    RUN(hostile_jpeg);
    RUN(hostile_files);
    return test_summary();
}
