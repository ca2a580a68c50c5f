/* A read-only ZIP reader over a memory buffer, written for hostile input: every size and
 * offset is checked against the buffer before use. */
#include "gen3d/zip.h"

#include <stdlib.h>
#include <string.h>
#include <zlib.h>

static uint16_t rd16(const unsigned char *p) { return (uint16_t)(p[0] | p[1] << 8); }
static uint32_t rd32(const unsigned char *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24; }
static uint64_t rd64(const unsigned char *p) { return (uint64_t)rd32(p) | (uint64_t)rd32(p + 4) << 32; }

/* [off, off+len) lies inside [0, size). */
static int in_bounds(uint64_t off, uint64_t len, uint64_t size) { return off <= size && len <= size - off; }

void g3d_zip_close(g3d_zip *zip)
{
    if (!zip) return;
    for (int64_t i = 0; i < zip->n_entries; i++) free(zip->entries[i].name);
    free(zip->entries);
    free(zip->label);
    memset(zip, 0, sizeof *zip);
}

/* Finds the end-of-central-directory record: the last signature within the final 64 KiB + 22. */
static int64_t find_eocd(const unsigned char *d, uint64_t n)
{
    if (n < 22) return -1;
    uint64_t lo = n > 22 + 65535 ? n - 22 - 65535 : 0;
    for (uint64_t i = n - 22 + 1; i-- > lo;)
        if (rd32(d + i) == 0x06054b50 && i + 22 + rd16(d + i + 20) == n) return (int64_t)i;
    return -1;
}

static g3d_status parse(g3d_zip *z)
{
    const unsigned char *d = z->data;
    uint64_t n = z->data_size;
    const char *L = z->label;
    int64_t eocd = find_eocd(d, n);
    if (eocd < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: not a zip archive (no end-of-directory record)", L);
    uint64_t count = rd16(d + eocd + 10), cd_size = rd32(d + eocd + 12), cd_off = rd32(d + eocd + 16);

    if (count == 0xffff || cd_size == 0xffffffffu || cd_off == 0xffffffffu) {
        /* ZIP64: the locator sits just before the EOCD and points at the ZIP64 record. */
        if (eocd < 20 || rd32(d + eocd - 20) != 0x07064b50)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: zip64 archive without a locator", L);
        uint64_t rec = rd64(d + eocd - 20 + 8);
        if (!in_bounds(rec, 56, n) || rd32(d + rec) != 0x06064b50)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: bad zip64 end-of-directory record", L);
        count = rd64(d + rec + 32);
        cd_size = rd64(d + rec + 40);
        cd_off = rd64(d + rec + 48);
    }
    if (!in_bounds(cd_off, cd_size, n)) return G3D_ERR(G3D_ERR_FORMAT, "%s: central directory lies outside the file", L);
    /* Each directory record is at least 46 bytes, so a count above cd_size/46 is a lie. */
    if (count > cd_size / 46) return G3D_ERR(G3D_ERR_FORMAT, "%s: central directory claims %llu entries in %llu bytes", L,
                                             (unsigned long long)count, (unsigned long long)cd_size);
    z->entries = g3d_calloc(count ? count : 1, sizeof *z->entries, "zip directory");
    if (!z->entries) return G3D_ERR_NOMEM;

    uint64_t p = cd_off, end = cd_off + cd_size;
    for (uint64_t i = 0; i < count; i++) {
        g3d_zip_entry *e = &z->entries[i];
        if (!in_bounds(p, 46, end) || rd32(d + p) != 0x02014b50)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: corrupt central directory record %llu", L, (unsigned long long)i);
        uint16_t flags = rd16(d + p + 8), nlen = rd16(d + p + 28), xlen = rd16(d + p + 30), clen = rd16(d + p + 32);
        uint64_t csize = rd32(d + p + 20), usize = rd32(d + p + 24), loff = rd32(d + p + 42);
        e->method = rd16(d + p + 10);
        e->crc32 = rd32(d + p + 16);
        if (!in_bounds(p + 46, (uint64_t)nlen + xlen + clen, end))
            return G3D_ERR(G3D_ERR_FORMAT, "%s: directory record %llu runs past the directory", L, (unsigned long long)i);
        if (flags & 1) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: encrypted zip entries are not supported", L);
        e->name = malloc((size_t)nlen + 1);
        if (!e->name) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", L);
        memcpy(e->name, d + p + 46, nlen);
        e->name[nlen] = 0;
        z->n_entries = (int64_t)i + 1;
        /* ZIP64 extra field: the 64-bit values appear in order, only for fields set to 0xffffffff. */
        for (uint64_t x = p + 46 + nlen, xe = x + xlen; x + 4 <= xe;) {
            uint16_t id = rd16(d + x), sz = rd16(d + x + 2);
            if (x + 4 + sz > xe) break;
            if (id == 0x0001) {
                uint64_t q = x + 4, qe = q + sz;
                if (usize == 0xffffffffu) { if (q + 8 > qe) break; usize = rd64(d + q); q += 8; }
                if (csize == 0xffffffffu) { if (q + 8 > qe) break; csize = rd64(d + q); q += 8; }
                if (loff == 0xffffffffu) { if (q + 8 > qe) break; loff = rd64(d + q); }
            }
            x += 4 + (uint64_t)sz;
        }
        /* The local header repeats name and extra lengths; the data follows them. */
        if (!in_bounds(loff, 30, n) || rd32(d + loff) != 0x04034b50)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s' has a bad local header", L, e->name);
        uint16_t lnlen = rd16(d + loff + 26), lxlen = rd16(d + loff + 28);
        if (lnlen != nlen || !in_bounds(loff + 30, nlen, n) || memcmp(d + loff + 30, e->name, nlen) != 0)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s': local header disagrees with the directory", L, e->name);
        if (rd16(d + loff + 8) != e->method)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s': local header disagrees with the directory", L, e->name);
        e->offset = loff + 30 + (uint64_t)lnlen + lxlen;
        e->comp_size = csize;
        e->size = usize;
        if (!in_bounds(e->offset, csize, n))
            return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s' extends past the end of the file (truncated?)", L, e->name);
        if (e->method != 0 && e->method != 8)
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: entry '%s' uses compression method %d (only stored and deflate)", L,
                           e->name, e->method);
        if (e->method == 0 && csize != usize)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: stored entry '%s' has different packed and unpacked sizes", L, e->name);
        p += 46 + (uint64_t)nlen + xlen + clen;
    }
    return G3D_OK;
}

g3d_status g3d_zip_open(g3d_zip *zip, const unsigned char *data, uint64_t n, const char *label)
{
    memset(zip, 0, sizeof *zip);
    zip->data = data;
    zip->data_size = n;
    zip->label = malloc(strlen(label) + 1);
    if (!zip->label) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    strcpy(zip->label, label);
    g3d_status rc = parse(zip);
    if (rc != G3D_OK) g3d_zip_close(zip);
    return rc;
}

int64_t g3d_zip_find(const g3d_zip *zip, const char *name)
{
    for (int64_t i = 0; i < zip->n_entries; i++)
        if (!strcmp(zip->entries[i].name, name)) return i;
    return -1;
}

const unsigned char *g3d_zip_stored_data(const g3d_zip *zip, int64_t i)
{
    if (i < 0 || i >= zip->n_entries) { G3D_ERR(G3D_ERR_ARG, "%s: no entry %lld", zip->label, (long long)i); return NULL; }
    const g3d_zip_entry *e = &zip->entries[i];
    if (e->method != 0) {
        G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: entry '%s' is compressed", zip->label, e->name);
        return NULL;
    }
    return zip->data + e->offset;
}

g3d_status g3d_zip_extract(const g3d_zip *zip, int64_t i, uint64_t max_entry_bytes, unsigned char **out, uint64_t *out_size)
{
    if (i < 0 || i >= zip->n_entries) return G3D_ERR(G3D_ERR_ARG, "%s: no entry %lld", zip->label, (long long)i);
    const g3d_zip_entry *e = &zip->entries[i];
    if (e->size > max_entry_bytes)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s' claims %llu bytes, above the limit of %llu", zip->label, e->name,
                       (unsigned long long)e->size, (unsigned long long)max_entry_bytes);
    unsigned char *buf = malloc(e->size ? (size_t)e->size : 1);
    if (!buf) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory for entry '%s'", zip->label, e->name);
    if (e->method == 0) {
        memcpy(buf, zip->data + e->offset, (size_t)e->size);
    } else {
        z_stream s;
        memset(&s, 0, sizeof s);
        if (inflateInit2(&s, -MAX_WBITS) != Z_OK) { free(buf); return G3D_ERR(G3D_ERR_INTERNAL, "zlib init failed"); }
        /* Feed in chunks that fit zlib's 32-bit counters; never write past e->size. */
        const unsigned char *src = zip->data + e->offset;
        uint64_t in_left = e->comp_size, out_done = 0;
        int zr = Z_OK;
        while (zr == Z_OK) {
            uInt in_chunk = in_left > 0x40000000u ? 0x40000000u : (uInt)in_left;
            uint64_t out_left = e->size - out_done;
            uInt out_chunk = out_left > 0x40000000u ? 0x40000000u : (uInt)out_left;
            s.next_in = (Bytef *)src;
            s.avail_in = in_chunk;
            s.next_out = buf + out_done;
            s.avail_out = out_chunk;
            zr = inflate(&s, Z_NO_FLUSH);
            src += in_chunk - s.avail_in;
            in_left -= in_chunk - s.avail_in;
            out_done += out_chunk - s.avail_out;
            if (zr == Z_OK && s.avail_out == out_chunk && s.avail_in == in_chunk) zr = Z_BUF_ERROR; /* no progress */
            if (zr == Z_BUF_ERROR && out_done == e->size && out_chunk == 0) zr = Z_DATA_ERROR; /* more output than declared */
        }
        inflateEnd(&s);
        if (zr != Z_STREAM_END || out_done != e->size) {
            free(buf);
            return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s' does not decompress to its declared %llu bytes", zip->label,
                           e->name, (unsigned long long)e->size);
        }
    }
    if ((uint32_t)crc32_z(crc32(0L, Z_NULL, 0), buf, (z_size_t)e->size) != e->crc32) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: entry '%s' fails its CRC check (corrupt)", zip->label, e->name);
    }
    *out = buf;
    *out_size = e->size;
    return G3D_OK;
}
