/* gen3d/zip.h - a read-only ZIP archive reader (for NPZ arrays and PyTorch checkpoints).
 *
 * Reads the central directory (ZIP64 too), supports stored and deflated entries (zlib),
 * and treats the archive as hostile: every offset and size is checked against the file,
 * local headers must agree with the central directory, CRC-32 is verified, and an entry's
 * uncompressed size is bounded (max_entry_bytes) so decompression bombs are rejected.
 *
 * The archive is read from a caller-owned memory buffer (e.g. a whole file read with
 * g3d_read_file, or an mmap); the buffer must outlive the g3d_zip.
 */
#ifndef G3D_ZIP_H
#define G3D_ZIP_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_zip_entry {
    char *name;              /* NUL-terminated, owned by the g3d_zip */
    uint64_t offset;         /* offset of the entry's data (after the local header) in the buffer */
    uint64_t comp_size;      /* bytes stored in the archive */
    uint64_t size;           /* uncompressed bytes */
    uint32_t crc32;
    int method;              /* 0 stored, 8 deflate */
} g3d_zip_entry;

typedef struct g3d_zip {
    const unsigned char *data; /* the archive bytes (not owned) */
    uint64_t data_size;
    g3d_zip_entry *entries;    /* (n_entries) */
    int64_t n_entries;
    char *label;               /* file name used in error messages (owned) */
} g3d_zip;

/* Parses the central directory of `data` (n bytes). `label` names the file in messages.
 * On failure *zip is zeroed and nothing needs freeing. */
g3d_status g3d_zip_open(g3d_zip *zip, const unsigned char *data, uint64_t n, const char *label);
/* Frees the entry table; NULL/zeroed is fine. Does not free the data buffer. */
void g3d_zip_close(g3d_zip *zip);
/* Index of the entry named `name`, or -1. */
int64_t g3d_zip_find(const g3d_zip *zip, const char *name);
/* Extracts entry i into a malloc'd buffer (caller frees), checking sizes and CRC.
 * Entries whose size exceeds max_entry_bytes are rejected. */
g3d_status g3d_zip_extract(const g3d_zip *zip, int64_t i, uint64_t max_entry_bytes,
                           unsigned char **out, uint64_t *out_size);
/* For a stored (uncompressed) entry: a pointer into the archive buffer, no copy. Returns NULL
 * (and sets the error) for compressed entries or bad bounds. */
const unsigned char *g3d_zip_stored_data(const g3d_zip *zip, int64_t i);

#ifdef __cplusplus
}
#endif
#endif /* G3D_ZIP_H */
