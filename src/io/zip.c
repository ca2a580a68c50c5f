/* Read-only ZIP reader: central directory (with ZIP64), stored and deflated entries.
 * The archive is untrusted: every field is bounds-checked before use, the local header
 * must repeat the central directory's name and method, and the CRC-32 is verified. */
#include "gen3d/zip.h"

#include <stdlib.h>
#include <string.h>
#include <zlib.h>

static uint16_t rd16(const unsigned char *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t rd32(const unsigned char *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
static uint64_t rd64(const unsigned char *p) { return (uint64_t)rd32(p) | ((uint64_t)rd32(p + 4) << 32); }

/* 1 if [off, off+len) lies inside a buffer of n bytes (no overflow). */
static int in_bounds(uint64_t off, uint64_t len, uint64_t n) { return off <= n && len <= n - off; }

#define EOCD_SIG 0x06054b50u
#define EOCD64_LOC_SIG 0x07064b50u
#define EOCD64_SIG 0x06064b50u
#define CDIR_SIG 0x02014b50u
#define LOCAL_SIG 0x04034b50u

/* Applies the ZIP64 extended-information extra field (id 1): it holds, in this order, only
 * those of size / comp_size / local offset whose 32-bit fields are 0xffffffff. */
static int apply_zip64(const unsigned char *extra, uint32_t extra_len, uint64_t *size,
                       uint64_t *comp, uint64_t *loc)
{
    uint32_t p = 0;
    int need = (*size == 0xffffffffu) + (*comp == 0xffffffffu) + (*loc == 0xffffffffu);
    if (!need) return 1;
    while (p + 4 <= extra_len) {
        uint16_t id = rd16(extra + p), len = rd16(extra + p + 2);
        const unsigned char *f = extra + p + 4;
        uint32_t q = 0;
        if (p + 4 + (uint32_t)len > extra_len) return 0;
        if (id == 1) {
            if (*size == 0xffffffffu) { if (q + 8 > len) return 0; *size = rd64(f + q); q += 8; }
            if (*comp == 0xffffffffu) { if (q + 8 > len) return 0; *comp = rd64(f + q); q += 8; }
            if (*loc == 0xffffffffu) { if (q + 8 > len) return 0; *loc = rd64(f + q); q += 8; }
            return 1;
        }
        p += 4 + (uint32_t)len;
    }
    return 0;
}

static char *dup_str(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}

void g3d_zip_close(g3d_zip *zip)
{
    if (!zip) return;
    for (int64_t i = 0; i < zip->n_entries; i++) free(zip->entries[i].name);
    free(zip->entries);
    free(zip->label);
    memset(zip, 0, sizeof *zip);
}

g3d_status g3d_zip_open(g3d_zip *zip, const unsigned char *data, uint64_t n, const char *label)
{
    uint64_t eocd = 0, cd_off, cd_size, count, p;
    int found = 0;
    const char *L = label ? label : "zip";
    g3d_status rc = G3D_OK;

    memset(zip, 0, sizeof *zip);
    if (n < 22) return G3D_ERR(G3D_ERR_FORMAT, "%s: not a zip archive (too short, %llu bytes)", L, (unsigned long long)n);
    /* The end record sits in the last 22 + 65535 (comment) bytes; search backwards. */
    for (uint64_t i = n - 22;; i--) {
        if (rd32(data + i) == EOCD_SIG && i + 22 + rd16(data + i + 20) == n) { eocd = i; found = 1; break; }
        if (i == 0 || n - i > 22 + 65535) break;
    }
    if (!found) return G3D_ERR(G3D_ERR_FORMAT, "%s: not a zip archive (no end of central directory record)", L);
    count = rd16(data + eocd + 10);
    cd_size = rd32(data + eocd + 12);
    cd_off = rd32(data + eocd + 16);
    if (count == 0xffff || cd_size == 0xffffffffu || cd_off == 0xffffffffu) {
        uint64_t loc, e64;
        if (eocd < 20 || rd32(data + eocd - 20) != EOCD64_LOC_SIG)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: ZIP64 end of central directory locator missing", L);
        loc = eocd - 20;
        e64 = rd64(data + loc + 8);
        if (!in_bounds(e64, 56, loc) || rd32(data + e64) != EOCD64_SIG)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: ZIP64 end of central directory record out of bounds or corrupt", L);
        count = rd64(data + e64 + 32);
        cd_size = rd64(data + e64 + 40);
        cd_off = rd64(data + e64 + 48);
    }
    if (!in_bounds(cd_off, cd_size, n))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: central directory (offset %llu, %llu bytes) lies past the end of the file (%llu bytes)",
                       L, (unsigned long long)cd_off, (unsigned long long)cd_size, (unsigned long long)n);
    /* Each record takes at least 46 bytes, which also bounds the allocation. */
    if (count > cd_size / 46)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: central directory claims %llu entries in %llu bytes", L,
                       (unsigned long long)count, (unsigned long long)cd_size);
    zip->data = data;
    zip->data_size = n;
    zip->label = dup_str(L);
    zip->entries = count ? calloc((size_t)count, sizeof *zip->entries) : NULL;
    if (!zip->label || (count && !zip->entries)) { g3d_zip_close(zip); return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", L); }

    p = cd_off;
    for (uint64_t i = 0; i < count; i++) {
        const unsigned char *c = data + p, *lh;
        g3d_zip_entry *e = &zip->entries[i];
        uint32_t name_len, extra_len, comment_len, lname, lextra;
        uint64_t loc, data_off;
        uint16_t flags;
        if (!in_bounds(p, 46, cd_off + cd_size) || rd32(c) != CDIR_SIG) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: central directory entry %llu is corrupt", L, (unsigned long long)i);
            goto fail;
        }
        flags = rd16(c + 8);
        e->method = rd16(c + 10);
        e->crc32 = rd32(c + 16);
        e->comp_size = rd32(c + 20);
        e->size = rd32(c + 24);
        name_len = rd16(c + 28);
        extra_len = rd16(c + 30);
        comment_len = rd16(c + 32);
        loc = rd32(c + 42);
        if (!in_bounds(p + 46, (uint64_t)name_len + extra_len + comment_len, cd_off + cd_size)) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: central directory entry %llu runs past the directory", L, (unsigned long long)i);
            goto fail;
        }
        e->name = malloc(name_len + 1u);
        if (!e->name) { rc = G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", L); goto fail; }
        memcpy(e->name, c + 46, name_len);
        e->name[name_len] = 0;
        zip->n_entries = (int64_t)i + 1;
        if (memchr(e->name, 0, name_len)) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: entry %llu has a NUL byte in its name", L, (unsigned long long)i);
            goto fail;
        }
        if (!apply_zip64(c + 46 + name_len, extra_len, &e->size, &e->comp_size, &loc)) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: ZIP64 extra field missing or truncated", L, e->name);
            goto fail;
        }
        if (flags & 1) { rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: %s: encrypted entries are not supported", L, e->name); goto fail; }
        if (e->method != 0 && e->method != 8) {
            rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: %s: compression method %d not supported (stored or deflate only)", L, e->name, e->method);
            goto fail;
        }
        if (e->method == 0 && e->comp_size != e->size) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: stored entry with compressed size %llu != size %llu", L, e->name,
                         (unsigned long long)e->comp_size, (unsigned long long)e->size);
            goto fail;
        }
        /* The local header must repeat the name and method; its sizes may be deferred to a
         * data descriptor (flag bit 3), so the central directory's sizes are authoritative. */
        if (!in_bounds(loc, 30, n) || rd32(data + loc) != LOCAL_SIG) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: local header at offset %llu is missing or out of bounds", L, e->name, (unsigned long long)loc);
            goto fail;
        }
        lh = data + loc;
        lname = rd16(lh + 26);
        lextra = rd16(lh + 28);
        if (rd16(lh + 8) != e->method || lname != name_len || !in_bounds(loc + 30, lname, n) || memcmp(lh + 30, e->name, name_len) != 0) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: local header disagrees with the central directory", L, e->name);
            goto fail;
        }
        if (!(rd16(lh + 6) & 8) && rd32(lh + 14) != e->crc32) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: local header CRC disagrees with the central directory", L, e->name);
            goto fail;
        }
        data_off = loc + 30 + lname + lextra;
        if (!in_bounds(data_off, e->comp_size, n)) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s: data (%llu bytes at offset %llu) runs past the end of the file (%llu bytes)",
                         L, e->name, (unsigned long long)e->comp_size, (unsigned long long)data_off, (unsigned long long)n);
            goto fail;
        }
        e->offset = data_off;
        p += 46 + (uint64_t)name_len + extra_len + comment_len;
    }
    return G3D_OK;
fail:
    g3d_zip_close(zip);
    return rc;
}

int64_t g3d_zip_find(const g3d_zip *zip, const char *name)
{
    for (int64_t i = 0; i < zip->n_entries; i++)
        if (strcmp(zip->entries[i].name, name) == 0) return i;
    return -1;
}

/* zlib's crc32 takes uInt lengths; feed large buffers in pieces. */
static uint32_t crc_of(const unsigned char *p, uint64_t n)
{
    uLong crc = crc32(0L, Z_NULL, 0);
    while (n) {
        uInt k = n > 0x40000000u ? 0x40000000u : (uInt)n;
        crc = crc32(crc, p, k);
        p += k;
        n -= k;
    }
    return (uint32_t)crc;
}

const unsigned char *g3d_zip_stored_data(const g3d_zip *zip, int64_t i)
{
    const g3d_zip_entry *e;
    if (i < 0 || i >= zip->n_entries) { G3D_ERR(G3D_ERR_ARG, "%s: no entry %lld", zip->label, (long long)i); return NULL; }
    e = &zip->entries[i];
    if (e->method != 0) { G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: %s: entry is compressed", zip->label, e->name); return NULL; }
    if (!in_bounds(e->offset, e->size, zip->data_size)) {
        G3D_ERR(G3D_ERR_FORMAT, "%s: %s: data runs past the end of the file", zip->label, e->name);
        return NULL;
    }
    return zip->data + e->offset;
}

g3d_status g3d_zip_extract(const g3d_zip *zip, int64_t i, uint64_t max_entry_bytes,
                           unsigned char **out, uint64_t *out_size)
{
    const g3d_zip_entry *e;
    unsigned char *buf;
    if (i < 0 || i >= zip->n_entries) return G3D_ERR(G3D_ERR_ARG, "%s: no entry %lld", zip->label, (long long)i);
    e = &zip->entries[i];
    if (e->size > max_entry_bytes)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: %s: entry of %llu bytes exceeds the limit of %llu bytes", zip->label, e->name,
                       (unsigned long long)e->size, (unsigned long long)max_entry_bytes);
    if (e->size > (uint64_t)SIZE_MAX - 1 || !in_bounds(e->offset, e->comp_size, zip->data_size))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: %s: entry out of bounds", zip->label, e->name);
    buf = malloc((size_t)e->size + 1);
    if (!buf) return G3D_ERR(G3D_ERR_NOMEM, "%s: %s: out of memory (%llu bytes)", zip->label, e->name, (unsigned long long)e->size);
    if (e->method == 0) {
        memcpy(buf, zip->data + e->offset, (size_t)e->size);
    } else {
        /* Inflate at most e->size bytes; a stream that wants more, or ends early, is corrupt. */
        z_stream zs;
        int zr = Z_OK;
        uint64_t in_left = e->comp_size, out_done = 0;
        const unsigned char *in = zip->data + e->offset;
        memset(&zs, 0, sizeof zs);
        if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) { free(buf); return G3D_ERR(G3D_ERR_NOMEM, "%s: zlib init failed", zip->label); }
        while (zr == Z_OK) {
            uInt ic = in_left > 0x40000000u ? 0x40000000u : (uInt)in_left;
            uint64_t room = e->size + 1 - out_done; /* one spare byte detects overlong streams */
            uInt oc = room > 0x40000000u ? 0x40000000u : (uInt)room;
            zs.next_in = (Bytef *)in;
            zs.avail_in = ic;
            zs.next_out = buf + out_done;
            zs.avail_out = oc;
            zr = inflate(&zs, Z_NO_FLUSH);
            in += ic - zs.avail_in;
            in_left -= ic - zs.avail_in;
            out_done += oc - zs.avail_out;
            if (zr == Z_BUF_ERROR && (in_left == 0 || out_done > e->size)) break;
            if (zr == Z_BUF_ERROR) zr = Z_OK;
        }
        inflateEnd(&zs);
        if (zr != Z_STREAM_END || out_done != e->size) {
            free(buf);
            return G3D_ERR(G3D_ERR_FORMAT, "%s: %s: corrupt deflate data (%s)", zip->label, e->name,
                           zr == Z_STREAM_END ? "size disagrees with the directory" : "stream error or truncated");
        }
    }
    if (crc_of(buf, e->size) != e->crc32) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: %s: CRC-32 mismatch (corrupt data)", zip->label, e->name);
    }
    buf[e->size] = 0;
    *out = buf;
    *out_size = e->size;
    return G3D_OK;
}
