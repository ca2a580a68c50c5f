/* libFuzzer target: the restricted unpickler. The input becomes archive/data.pkl of a stored
 * zip, next to one 64-byte storage "archive/data/0", and goes through the checkpoint reader. */
#include "gen3d/ckpt.h"

#include <stdlib.h>
#include <string.h>
#include <zlib.h>

static size_t put16(unsigned char *p, unsigned v) { p[0] = (unsigned char)v; p[1] = (unsigned char)(v >> 8); return 2; }
static size_t put32(unsigned char *p, uint32_t v) { put16(p, v & 0xffff); put16(p + 2, v >> 16); return 4; }

/* Appends a stored entry's local header and data; returns the new length. */
static size_t local_entry(unsigned char *z, size_t o, const char *name, const unsigned char *d, size_t n, uint32_t *crc)
{
    size_t nl = strlen(name);
    *crc = (uint32_t)crc32(0, d, (uInt)n);
    o += put32(z + o, 0x04034b50); o += put16(z + o, 20); o += put16(z + o, 0); o += put16(z + o, 0);
    o += put16(z + o, 0); o += put16(z + o, 0); o += put32(z + o, *crc); o += put32(z + o, (uint32_t)n);
    o += put32(z + o, (uint32_t)n); o += put16(z + o, (unsigned)nl); o += put16(z + o, 0);
    memcpy(z + o, name, nl); o += nl;
    memcpy(z + o, d, n);
    return o + n;
}

static size_t central_entry(unsigned char *z, size_t o, const char *name, size_t n, uint32_t crc, size_t at)
{
    size_t nl = strlen(name);
    o += put32(z + o, 0x02014b50); o += put16(z + o, 20); o += put16(z + o, 20); o += put16(z + o, 0);
    o += put16(z + o, 0); o += put16(z + o, 0); o += put16(z + o, 0); o += put32(z + o, crc);
    o += put32(z + o, (uint32_t)n); o += put32(z + o, (uint32_t)n); o += put16(z + o, (unsigned)nl);
    o += put16(z + o, 0); o += put16(z + o, 0); o += put16(z + o, 0); o += put16(z + o, 0);
    o += put32(z + o, 0); o += put32(z + o, (uint32_t)at);
    memcpy(z + o, name, nl);
    return o + nl;
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t n)
{
    if (n > (1 << 20)) return 0;
    unsigned char storage[64] = {0};
    unsigned char *z = malloc(n + 512);
    if (!z) return 0;
    uint32_t c1, c2;
    size_t o = local_entry(z, 0, "archive/data.pkl", data, n, &c1);
    size_t second = o;
    o = local_entry(z, o, "archive/data/0", storage, sizeof storage, &c2);
    size_t cd = o;
    o = central_entry(z, o, "archive/data.pkl", n, c1, 0);
    o = central_entry(z, o, "archive/data/0", sizeof storage, c2, second);
    size_t cds = o - cd;
    o += put32(z + o, 0x06054b50); o += put16(z + o, 0); o += put16(z + o, 0); o += put16(z + o, 2);
    o += put16(z + o, 2); o += put32(z + o, (uint32_t)cds); o += put32(z + o, (uint32_t)cd); o += put16(z + o, 0);
    g3d_ckpt *ck;
    if (g3d_ckpt_open_memory(z, o, "fuzz.pth", &ck) == G3D_OK) g3d_ckpt_free(ck);
    free(z);
    return 0;
}
