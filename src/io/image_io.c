/* Image files: JPEG decoding through libjpeg-turbo set up as PIL and OpenCV use it, PNG
 * decoding through stb_image, PNG encoding with zlib. */
#include "gen3d/imageio.h"

#include <math.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include <jpeglib.h>       /* Debian's libjpeg62-turbo */
#include <jerror.h>
#include <stb/stb_image.h> /* decoder from Debian's libstb */

/* Images are small compared with this cap; it guards against reading huge non-image files. */
#define MAX_IMAGE_FILE_BYTES ((size_t)1 << 31)

/* JPEG files start with the SOI marker followed by another marker. */
static int is_jpeg(const unsigned char *data, size_t n)
{
    return n >= 3 && data[0] == 0xFF && data[1] == 0xD8 && data[2] == 0xFF;
}

/* Reads the file and checks the header; returns the stored size and channel count (not for
 * JPEG files, whose header the JPEG decoder reads). */
static g3d_status read_checked(const char *path, unsigned char **data, size_t *n, int *w, int *h, int *c)
{
    G3D_TRY(g3d_read_file(path, MAX_IMAGE_FILE_BYTES, data, n));
    if (*n == 0) {
        free(*data);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: empty file", path);
    }
    if (is_jpeg(*data, *n)) return G3D_OK;   /* libjpeg checks the header */
    if (*n > INT32_MAX || !stbi_info_from_memory(*data, (int)*n, w, h, c)) {
        free(*data);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not a PNG or JPEG image (or corrupt header)", path);
    }
    if (*w < 1 || *h < 1 || *w > G3D_MAX_IMAGE_SIDE || *h > G3D_MAX_IMAGE_SIDE) {
        free(*data);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: image size %dx%d out of range (sides 1..%d)", path, *w, *h,
                       G3D_MAX_IMAGE_SIDE);
    }
    return G3D_OK;
}

/* ---- JPEG decoder ----------------------------------------------------------------------- */

/* libjpeg reports fatal errors through error_exit, which must not return: jump back out. */
typedef struct jpeg_err {
    struct jpeg_error_mgr mgr;
    jmp_buf env;
    char msg[JMSG_LENGTH_MAX];
} jpeg_err;

static void jpeg_fail(j_common_ptr cinfo)
{
    jpeg_err *e = (jpeg_err *)cinfo->err;
    e->mgr.format_message(cinfo, e->msg);
    longjmp(e->env, 1);
}

/* Warnings about data libjpeg decodes around (stray bytes before a marker) stay quiet, as in
 * PIL and OpenCV; a file that ends early is an error, as in PIL (libjpeg would fill the rest
 * with grey). */
static void jpeg_warning(j_common_ptr cinfo, int level)
{
    if (level < 0 && cinfo->err->msg_code == JWRN_JPEG_EOF) jpeg_fail(cinfo);
}

/* Decodes JPEG data as `channels` channels (1 grey, 3 RGB, 0 as stored) with the decoder's
 * defaults (accurate integer IDCT, fancy chroma upsampling), which are what PIL's Image.open
 * and OpenCV's imread use: the pixels equal theirs bit for bit. EXIF orientation is not
 * applied (as in PIL; OpenCV's imread rotates). */
static g3d_status jpeg_decode(const char *path, const unsigned char *data, size_t n, int channels, g3d_image *img)
{
    struct jpeg_decompress_struct cinfo;
    jpeg_err err;
    unsigned char *volatile row = NULL;
    volatile g3d_status rc = G3D_OK;
    cinfo.err = jpeg_std_error(&err.mgr);
    err.mgr.error_exit = jpeg_fail;
    err.mgr.emit_message = jpeg_warning;
    if (setjmp(err.env)) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: cannot decode JPEG (%s)", path, err.msg);
        goto done;
    }
    jpeg_create_decompress(&cinfo);
    jpeg_mem_src(&cinfo, data, (unsigned long)n);
    jpeg_read_header(&cinfo, TRUE);
    if (cinfo.jpeg_color_space == JCS_CMYK || cinfo.jpeg_color_space == JCS_YCCK) {
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: CMYK JPEG images are not supported", path);
        goto done;
    }
    if (cinfo.image_width < 1 || cinfo.image_height < 1 || cinfo.image_width > G3D_MAX_IMAGE_SIDE ||
        cinfo.image_height > G3D_MAX_IMAGE_SIDE) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: image size %ux%u out of range (sides 1..%d)", path, cinfo.image_width,
                     cinfo.image_height, G3D_MAX_IMAGE_SIDE);
        goto done;
    }
    int out_c = channels ? channels : cinfo.num_components == 1 ? 1 : 3;
    cinfo.out_color_space = out_c == 3 ? JCS_RGB : JCS_GRAYSCALE;
    jpeg_start_decompress(&cinfo);
    int w = (int)cinfo.output_width, h = (int)cinfo.output_height;
    rc = g3d_image_create(img, w, h, out_c);
    if (rc == G3D_OK && !(row = malloc((size_t)w * out_c))) rc = G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path);
    while (rc == G3D_OK && cinfo.output_scanline < cinfo.output_height) {
        float *dst = img->data + (size_t)cinfo.output_scanline * w * out_c;
        JSAMPROW rows[1] = {(JSAMPROW)row};
        jpeg_read_scanlines(&cinfo, rows, 1);
        for (size_t i = 0; i < (size_t)w * out_c; i++) dst[i] = (float)row[i] / 255.0f;
    }
    if (rc == G3D_OK) jpeg_finish_decompress(&cinfo);
done:
    jpeg_destroy_decompress(&cinfo);
    free(row);
    if (rc != G3D_OK) g3d_image_free(img);
    return rc;
}

g3d_status g3d_image_load(const char *path, int channels, g3d_image *img)
{
    unsigned char *data;
    size_t n;
    int w, h, c, is16;
    memset(img, 0, sizeof *img);
    if (channels != 0 && channels != 1 && channels != 3)
        return G3D_ERR(G3D_ERR_ARG, "%s: can only load 1 or 3 channels, not %d", path, channels);
    G3D_TRY(read_checked(path, &data, &n, &w, &h, &c));
    if (is_jpeg(data, n)) {
        g3d_status rc = jpeg_decode(path, data, n, channels, img);
        free(data);
        return rc;
    }
    int out_c = channels ? channels : (c >= 3 ? 3 : 1);
    is16 = stbi_is_16_bit_from_memory(data, (int)n);
    void *px = is16 ? (void *)stbi_load_16_from_memory(data, (int)n, &w, &h, &c, out_c)
                    : (void *)stbi_load_from_memory(data, (int)n, &w, &h, &c, out_c);
    free(data);
    if (!px) return G3D_ERR(G3D_ERR_FORMAT, "%s: cannot decode image (%s)", path, stbi_failure_reason());
    g3d_status rc = g3d_image_create(img, w, h, out_c);
    if (rc == G3D_OK) {
        size_t total = g3d_image_size(img);
        float maxv = is16 ? 65535.0f : 255.0f; /* divide (not multiply by 1/max) so k/max round-trips exactly */
        for (size_t i = 0; i < total; i++)
            img->data[i] = (is16 ? (float)((uint16_t *)px)[i] : (float)((uint8_t *)px)[i]) / maxv;
    }
    stbi_image_free(px);
    return rc;
}

g3d_status g3d_image_load_u16(const char *path, g3d_image *img)
{
    unsigned char *data;
    size_t n;
    int w, h, c;
    memset(img, 0, sizeof *img);
    G3D_TRY(read_checked(path, &data, &n, &w, &h, &c));
    if (is_jpeg(data, n) || !stbi_is_16_bit_from_memory(data, (int)n)) {
        free(data);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: 16-bit PNG expected, got an 8-bit image", path);
    }
    uint16_t *px = stbi_load_16_from_memory(data, (int)n, &w, &h, &c, 1);
    free(data);
    if (!px) return G3D_ERR(G3D_ERR_FORMAT, "%s: cannot decode image (%s)", path, stbi_failure_reason());
    g3d_status rc = g3d_image_create(img, w, h, 1);
    if (rc == G3D_OK)
        for (size_t i = 0; i < (size_t)w * (size_t)h; i++) img->data[i] = (float)px[i];
    stbi_image_free(px);
    return rc;
}

/* ---- PNG encoder ------------------------------------------------------------------------ */

static void put_be32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24); p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);  p[3] = (unsigned char)v;
}

/* Appends one chunk (length, type, data, CRC over type + data). */
static unsigned char *put_chunk(unsigned char *p, const char *type, const unsigned char *data, uint32_t len)
{
    put_be32(p, len);
    memcpy(p + 4, type, 4);
    if (len) memcpy(p + 8, data, len);
    uLong crc = crc32(0L, p + 4, 4 + len);
    put_be32(p + 8 + len, (uint32_t)crc);
    return p + 12 + len;
}

g3d_status g3d_png_encode(const void *px, int w, int h, int c, int bits, unsigned char **out, size_t *out_n)
{
    size_t bps = bits == 16 ? 2 : 1, row, raw_n;
    if ((c != 1 && c != 3) || (bits != 8 && bits != 16) || w < 1 || h < 1)
        return G3D_ERR(G3D_ERR_ARG, "PNG encoder: unsupported layout %dx%d, %d channels, %d bits", w, h, c, bits);
    if (!g3d_size_mul3((size_t)w, (size_t)c, bps, &row) || !g3d_size_mul(row + 1, (size_t)h, &raw_n))
        return G3D_ERR(G3D_ERR_NOMEM, "PNG encoder: size overflow");
    unsigned char *raw = malloc(raw_n);
    if (!raw) return G3D_ERR(G3D_ERR_NOMEM, "PNG encoder: out of memory");
    /* Filter type 0 (none) on every row; PNG stores 16-bit samples big-endian. */
    for (int y = 0; y < h; y++) {
        unsigned char *r = raw + (size_t)y * (row + 1);
        r[0] = 0;
        if (bits == 8) {
            memcpy(r + 1, (const uint8_t *)px + (size_t)y * w * c, row);
        } else {
            const uint16_t *s = (const uint16_t *)px + (size_t)y * w * c;
            for (size_t i = 0; i < (size_t)w * c; i++) {
                r[1 + 2 * i] = (unsigned char)(s[i] >> 8);
                r[2 + 2 * i] = (unsigned char)s[i];
            }
        }
    }
    uLong zcap = compressBound((uLong)raw_n);
    unsigned char *buf = malloc(8 + 25 + 12 + zcap + 12);
    if (!buf) { free(raw); return G3D_ERR(G3D_ERR_NOMEM, "PNG encoder: out of memory"); }
    unsigned char *z = buf + 8 + 25 + 8; /* compress straight into the IDAT chunk's data */
    uLongf zn = zcap;
    if (compress2(z, &zn, raw, (uLong)raw_n, 6) != Z_OK) {
        free(raw);
        free(buf);
        return G3D_ERR(G3D_ERR_INTERNAL, "PNG encoder: deflate failed");
    }
    free(raw);
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    unsigned char ihdr[13];
    put_be32(ihdr, (uint32_t)w);
    put_be32(ihdr + 4, (uint32_t)h);
    ihdr[8] = (unsigned char)bits;
    ihdr[9] = c == 3 ? 2 : 0; /* colour type: truecolour or grey */
    ihdr[10] = ihdr[11] = ihdr[12] = 0;
    memcpy(buf, sig, 8);
    unsigned char *p = put_chunk(buf + 8, "IHDR", ihdr, 13);
    /* IDAT data already sits at p + 8: write the header and CRC around it. */
    put_be32(p, (uint32_t)zn);
    memcpy(p + 4, "IDAT", 4);
    put_be32(p + 8 + zn, (uint32_t)crc32(0L, p + 4, 4 + (uInt)zn));
    p += 12 + zn;
    p = put_chunk(p, "IEND", NULL, 0);
    *out = buf;
    *out_n = (size_t)(p - buf);
    return G3D_OK;
}

static g3d_status save_samples(const char *path, const g3d_image *img, int bits, float scale)
{
    size_t n = g3d_image_size(img);
    void *px;
    unsigned char *png;
    size_t png_n;
    if (img->c != 1 && img->c != 3)
        return G3D_ERR(G3D_ERR_ARG, "%s: PNG output needs 1 or 3 channels, image has %d", path, img->c);
    px = malloc(n * (bits == 16 ? 2 : 1));
    if (!px) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path);
    float maxv = bits == 16 ? 65535.0f : 255.0f;
    for (size_t i = 0; i < n; i++) {
        float v = img->data[i] * scale;
        v = v != v ? 0.0f : (v < 0 ? 0 : (v > maxv ? maxv : v));
        if (bits == 16) ((uint16_t *)px)[i] = (uint16_t)lrintf(v);
        else ((uint8_t *)px)[i] = (uint8_t)lrintf(v);
    }
    g3d_status rc = g3d_png_encode(px, img->w, img->h, img->c, bits, &png, &png_n);
    free(px);
    if (rc != G3D_OK) { g3d_error_prefix(path); return rc; }
    rc = g3d_write_file_atomic(path, png, png_n);
    free(png);
    return rc;
}

g3d_status g3d_image_save_png(const char *path, const g3d_image *img, int bits)
{
    if (bits != 8 && bits != 16) return G3D_ERR(G3D_ERR_ARG, "%s: PNG bit depth must be 8 or 16, not %d", path, bits);
    return save_samples(path, img, bits, bits == 16 ? 65535.0f : 255.0f);
}

g3d_status g3d_image_save_png_u16(const char *path, const g3d_image *img)
{
    return save_samples(path, img, 16, 1.0f);
}
