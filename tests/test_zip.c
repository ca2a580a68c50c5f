/* ZIP reader: archives built here by a minimal writer (stored, deflated, ZIP64 fields),
 * then hostile variants of them. */
#include "gen3d/npy.h"
#include "gen3d/zip.h"
#include "testutil.h"

#include <zlib.h>

typedef struct { unsigned char *b; size_t n, cap; } buf_t;

static void put(buf_t *w, const void *p, size_t n)
{
    if (w->n + n > w->cap) {
        w->cap = (w->n + n) * 2 + 64;
        w->b = realloc(w->b, w->cap);
    }
    memcpy(w->b + w->n, p, n);
    w->n += n;
}
static void p16(buf_t *w, unsigned v) { unsigned char b[2] = {(unsigned char)v, (unsigned char)(v >> 8)}; put(w, b, 2); }
static void p32(buf_t *w, uint32_t v) { p16(w, v & 0xffff); p16(w, v >> 16); }
static void p64(buf_t *w, uint64_t v) { p32(w, (uint32_t)v); p32(w, (uint32_t)(v >> 32)); }

typedef struct { const char *name; const unsigned char *data; size_t n; int method; int zip64; } member_t;

/* Writes a complete archive; zip64 members carry their sizes and offset in a ZIP64 extra
 * field, and any zip64 member makes the end records ZIP64 too. */
static buf_t build_zip(const member_t *m, int count)
{
    buf_t w = {0}, cd = {0};
    int any64 = 0;
    for (int i = 0; i < count; i++) {
        unsigned char *comp = NULL;
        size_t clen = m[i].n;
        uint32_t crc = (uint32_t)crc32(crc32(0, Z_NULL, 0), m[i].data, (uInt)m[i].n);
        uint32_t off = (uint32_t)w.n;
        size_t nl = strlen(m[i].name);
        if (m[i].method == 8) {
            z_stream zs;
            memset(&zs, 0, sizeof zs);
            deflateInit2(&zs, 9, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
            comp = malloc(deflateBound(&zs, (uLong)m[i].n));
            zs.next_in = (Bytef *)m[i].data;
            zs.avail_in = (uInt)m[i].n;
            zs.next_out = comp;
            zs.avail_out = (uInt)deflateBound(&zs, (uLong)m[i].n);
            deflate(&zs, Z_FINISH);
            clen = zs.total_out;
            deflateEnd(&zs);
        }
        any64 |= m[i].zip64;
        p32(&w, 0x04034b50); p16(&w, 20); p16(&w, 0); p16(&w, (unsigned)m[i].method); p16(&w, 0); p16(&w, 0);
        p32(&w, crc); p32(&w, (uint32_t)clen); p32(&w, (uint32_t)m[i].n); p16(&w, (unsigned)nl); p16(&w, 0);
        put(&w, m[i].name, nl);
        put(&w, comp ? comp : m[i].data, clen);
        free(comp);
        p32(&cd, 0x02014b50); p16(&cd, 45); p16(&cd, 45); p16(&cd, 0); p16(&cd, (unsigned)m[i].method);
        p16(&cd, 0); p16(&cd, 0); p32(&cd, crc);
        p32(&cd, m[i].zip64 ? 0xffffffffu : (uint32_t)clen);
        p32(&cd, m[i].zip64 ? 0xffffffffu : (uint32_t)m[i].n);
        p16(&cd, (unsigned)nl); p16(&cd, m[i].zip64 ? 28 : 0); p16(&cd, 0); p16(&cd, 0); p16(&cd, 0); p32(&cd, 0);
        p32(&cd, m[i].zip64 ? 0xffffffffu : off);
        put(&cd, m[i].name, nl);
        if (m[i].zip64) { p16(&cd, 1); p16(&cd, 24); p64(&cd, m[i].n); p64(&cd, clen); p64(&cd, off); }
    }
    uint64_t cd_off = w.n;
    put(&w, cd.b, cd.n);
    if (any64) {
        uint64_t e64 = w.n;
        p32(&w, 0x06064b50); p64(&w, 44); p16(&w, 45); p16(&w, 45); p32(&w, 0); p32(&w, 0);
        p64(&w, (uint64_t)count); p64(&w, (uint64_t)count); p64(&w, cd.n); p64(&w, cd_off);
        p32(&w, 0x07064b50); p32(&w, 0); p64(&w, e64); p32(&w, 1);
    }
    p32(&w, 0x06054b50); p16(&w, 0); p16(&w, 0);
    p16(&w, any64 ? 0xffff : (unsigned)count); p16(&w, any64 ? 0xffff : (unsigned)count);
    p32(&w, any64 ? 0xffffffffu : (uint32_t)cd.n); p32(&w, any64 ? 0xffffffffu : (uint32_t)cd_off); p16(&w, 0);
    free(cd.b);
    return w;
}

static unsigned char payload[5000];
static void fill_payload(void)
{
    for (size_t i = 0; i < sizeof payload; i++) payload[i] = (unsigned char)((i * 7) % 13 + (i / 100));
}

static int extract_equals(const g3d_zip *z, const char *name, const unsigned char *ref, size_t n)
{
    unsigned char *out = NULL;
    uint64_t sz = 0;
    int64_t i = g3d_zip_find(z, name);
    if (i < 0 || g3d_zip_extract(z, i, 1u << 20, &out, &sz) != G3D_OK) return 0;
    int ok = sz == n && memcmp(out, ref, n) == 0;
    free(out);
    return ok;
}

TEST(stored_and_deflated)
{
    fill_payload();
    member_t m[3] = {{"a.bin", payload, 1000, 0, 0}, {"dir/b.npy", payload, sizeof payload, 8, 0}, {"empty", payload, 0, 0, 0}};
    buf_t w = build_zip(m, 3);
    g3d_zip z;
    CHECK_OK(g3d_zip_open(&z, w.b, w.n, "t.zip"));
    CHECK(z.n_entries == 3);
    CHECK(extract_equals(&z, "a.bin", payload, 1000));
    CHECK(extract_equals(&z, "dir/b.npy", payload, sizeof payload));
    CHECK(extract_equals(&z, "empty", payload, 0));
    CHECK(z.entries[1].method == 8 && z.entries[1].comp_size < sizeof payload);
    CHECK(g3d_zip_find(&z, "missing") == -1);
    const unsigned char *p = g3d_zip_stored_data(&z, 0);
    CHECK(p && memcmp(p, payload, 1000) == 0);
    CHECK(g3d_zip_stored_data(&z, 1) == NULL); /* compressed */
    g3d_zip_close(&z);
    free(w.b);
}

TEST(zip64_fields)
{
    fill_payload();
    member_t m[2] = {{"x", payload, 777, 0, 1}, {"y", payload, 3000, 8, 1}};
    buf_t w = build_zip(m, 2);
    g3d_zip z;
    CHECK_OK(g3d_zip_open(&z, w.b, w.n, "t64.zip"));
    CHECK(z.n_entries == 2);
    CHECK(extract_equals(&z, "x", payload, 777));
    CHECK(extract_equals(&z, "y", payload, 3000));
    g3d_zip_close(&z);
    free(w.b);
}

/* Offset of the first central directory record in an archive from build_zip. */
static size_t cd_start(const buf_t *w)
{
    for (size_t i = 0; i + 4 <= w->n; i++)
        if (w->b[i] == 0x50 && w->b[i + 1] == 0x4b && w->b[i + 2] == 1 && w->b[i + 3] == 2) return i;
    return 0;
}

TEST(hostile)
{
    fill_payload();
    member_t m[1] = {{"d.bin", payload, sizeof payload, 8, 0}};
    member_t ms[1] = {{"s.bin", payload, 100, 0, 0}};
    buf_t w = build_zip(m, 1);
    g3d_zip z;
    unsigned char *out;
    uint64_t sz;

    /* empty and truncated archives */
    CHECK_FAILS(g3d_zip_open(&z, w.b, 0, "empty.zip"));
    CHECK_FAILS(g3d_zip_open(&z, w.b, w.n - 5, "truncated.zip"));
    CHECK_FAILS(g3d_zip_open(&z, w.b + 40, w.n - 40, "headless.zip"));

    /* central directory offset past the end */
    buf_t c = {0};
    put(&c, w.b, w.n);
    c.b[c.n - 6] = 0xff; c.b[c.n - 5] = 0xff; c.b[c.n - 4] = 0xff; c.b[c.n - 3] = 0x7f;
    CHECK_FAILS(g3d_zip_open(&z, c.b, c.n, "cdpast.zip"));

    /* compressed size past the end of the file */
    memcpy(c.b, w.b, w.n);
    size_t cd = cd_start(&c);
    c.b[cd + 20] = 0xff; c.b[cd + 21] = 0xff; c.b[cd + 22] = 0xff; c.b[cd + 23] = 0x0f;
    CHECK_FAILS(g3d_zip_open(&z, c.b, c.n, "sizepast.zip"));

    /* local header name disagrees with the central directory */
    memcpy(c.b, w.b, w.n);
    c.b[30] = 'X';
    CHECK_FAILS(g3d_zip_open(&z, c.b, c.n, "mismatch.zip"));

    /* local header offset pointing nowhere */
    memcpy(c.b, w.b, w.n);
    c.b[cd + 42] = 3;
    CHECK_FAILS(g3d_zip_open(&z, c.b, c.n, "badlocal.zip"));

    /* wrong CRC in both headers: opens, extraction fails */
    memcpy(c.b, w.b, w.n);
    c.b[14] ^= 1; c.b[cd + 16] ^= 1;
    CHECK_OK(g3d_zip_open(&z, c.b, c.n, "crc.zip"));
    CHECK_FAILS(g3d_zip_extract(&z, 0, 1u << 20, &out, &sz));
    g3d_zip_close(&z);

    /* corrupt deflate stream */
    memcpy(c.b, w.b, w.n);
    for (size_t i = 40; i < 60; i++) c.b[i] ^= 0x5a;
    CHECK_OK(g3d_zip_open(&z, c.b, c.n, "inflate.zip"));
    CHECK_FAILS(g3d_zip_extract(&z, 0, 1u << 20, &out, &sz));
    g3d_zip_close(&z);

    /* declared size smaller than the stream inflates to (overlong stream) */
    memcpy(c.b, w.b, w.n);
    c.b[cd + 24] = 10; c.b[cd + 25] = 0;
    CHECK_OK(g3d_zip_open(&z, c.b, c.n, "overlong.zip"));
    CHECK_FAILS(g3d_zip_extract(&z, 0, 1u << 20, &out, &sz));
    g3d_zip_close(&z);

    /* declared size larger than the stream inflates to */
    memcpy(c.b, w.b, w.n);
    c.b[cd + 24] = 0xff; c.b[cd + 25] = 0x0f;
    CHECK_OK(g3d_zip_open(&z, c.b, c.n, "short.zip"));
    CHECK_FAILS(g3d_zip_extract(&z, 0, 1u << 20, &out, &sz));
    g3d_zip_close(&z);

    /* bomb guard: entry larger than the caller's limit */
    CHECK_OK(g3d_zip_open(&z, w.b, w.n, "bomb.zip"));
    CHECK_FAILS(g3d_zip_extract(&z, 0, 1000, &out, &sz));
    CHECK_FAILS(g3d_zip_extract(&z, 5, 1u << 20, &out, &sz));
    g3d_zip_close(&z);

    /* stored entry whose sizes disagree */
    buf_t s = build_zip(ms, 1);
    size_t scd = cd_start(&s);
    s.b[scd + 24] = 99;
    CHECK_FAILS(g3d_zip_open(&z, s.b, s.n, "stored.zip"));
    /* entry count larger than the directory can hold */
    s.b[scd + 24] = 100;
    s.b[s.n - 12] = 0xff; s.b[s.n - 11] = 0x7f;
    CHECK_FAILS(g3d_zip_open(&z, s.b, s.n, "count.zip"));
    CHECK(strstr(g3d_error_message(), "count.zip") != NULL);
    free(s.b);
    free(c.b);
    free(w.b);
}

TEST(npz_members)
{
    /* An NPZ without arr_0: NULL picks the first member, names work with or without ".npy",
     * an unknown name is reported. */
    float v1[3] = {1.5f, -2.0f, 3.25f}, v2[2] = {7.0f, 8.0f};
    int64_t s1[1] = {3}, s2[2] = {1, 2};
    unsigned char *b1, *b2;
    size_t n1, n2;
    CHECK_OK(g3d_npy_save(test_tmp("m1.npy"), v1, 1, s1));
    CHECK_OK(g3d_npy_save(test_tmp("m2.npy"), v2, 2, s2));
    CHECK_OK(g3d_read_file(test_tmp("m1.npy"), 1 << 20, &b1, &n1));
    CHECK_OK(g3d_read_file(test_tmp("m2.npy"), 1 << 20, &b2, &n2));
    member_t m[2] = {{"first.npy", b1, n1, 8, 0}, {"second.npy", b2, n2, 0, 0}};
    buf_t w = build_zip(m, 2);
    CHECK_OK(g3d_write_file_atomic(test_tmp("two.npz"), w.b, w.n));
    g3d_array a;
    CHECK_OK(g3d_npz_load(test_tmp("two.npz"), NULL, &a));
    CHECK(a.ndim == 1 && a.shape[0] == 3 && memcmp(a.data, v1, sizeof v1) == 0);
    g3d_array_free(&a);
    CHECK_OK(g3d_npz_load(test_tmp("two.npz"), "second", &a));
    CHECK(a.ndim == 2 && a.shape[1] == 2 && memcmp(a.data, v2, sizeof v2) == 0);
    g3d_array_free(&a);
    CHECK_FAILS(g3d_npz_load(test_tmp("two.npz"), "third", &a));
    CHECK(strstr(g3d_error_message(), "two.npz") && strstr(g3d_error_message(), "third"));
    free(w.b);
    free(b1);
    free(b2);
}

int main(void)
{
    RUN(stored_and_deflated);
    RUN(zip64_fields);
    RUN(hostile);
    RUN(npz_members);
    return test_summary();
}
