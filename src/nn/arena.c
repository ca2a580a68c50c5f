/* The activation arena: a stack of chunks addressed by one running offset. A request that
 * does not fit in the current chunk starts the next chunk (allocated on demand, kept for
 * reuse); resetting to 0 with more than one chunk replaces them all by one chunk of the peak
 * size, so a model's second forward pass runs in one block without allocating. */
#include "nn/nn_int.h"

#include <stdlib.h>

typedef struct chunk {
    char *mem;
    size_t start, cap; /* covers offsets [start, start + cap) */
} chunk;

struct g3d_nn_arena {
    chunk *ch;
    int n, cur;
    size_t top, peak;
};

static int add_chunk(g3d_nn_arena *a, size_t start, size_t cap)
{
    chunk *c = realloc(a->ch, sizeof(chunk) * (size_t)(a->n + 1));
    if (!c) return 0;
    a->ch = c;
    char *mem = aligned_alloc(64, cap);
    if (!mem) return 0;
    a->ch[a->n++] = (chunk){mem, start, cap};
    return 1;
}

static size_t rup64(size_t x) { return (x + 63) / 64 * 64; }

g3d_nn_arena *g3d_nn_arena_new(size_t bytes)
{
    g3d_nn_arena *a = calloc(1, sizeof *a);
    if (!a) return NULL;
    if (bytes && !add_chunk(a, 0, rup64(bytes))) {
        g3d_nn_arena_free(a);
        return NULL;
    }
    return a;
}

void g3d_nn_arena_free(g3d_nn_arena *a)
{
    if (!a) return;
    for (int i = 0; i < a->n; i++) free(a->ch[i].mem);
    free(a->ch);
    free(a);
}

float *g3d_nn_arena_floats(g3d_nn_arena *a, size_t n)
{
    if (n > ((size_t)1 << 60) / sizeof(float)) {
        G3D_ERR(G3D_ERR_NOMEM, "arena: absurd request of %zu floats", n);
        return NULL;
    }
    const size_t bytes = rup64(n ? n * sizeof(float) : 64);
    /* the chunk holding the top, then later chunks, until one fits */
    while (a->cur < a->n) {
        chunk *c = &a->ch[a->cur];
        size_t off = a->top > c->start ? a->top : c->start;
        if (a->top < c->start + c->cap && off + bytes <= c->start + c->cap) {
            a->top = off + bytes;
            if (a->top > a->peak) a->peak = a->top;
            return (float *)(c->mem + (off - c->start));
        }
        if (a->cur + 1 == a->n) break;
        a->cur++;
    }
    size_t start = a->n ? a->ch[a->n - 1].start + a->ch[a->n - 1].cap : 0;
    size_t cap = a->n ? a->ch[a->n - 1].cap : 0;
    cap = cap * 2 > bytes ? cap * 2 : bytes;
    if (cap < ((size_t)1 << 20)) cap = (size_t)1 << 20;
    if (!add_chunk(a, start, cap)) {
        G3D_ERR(G3D_ERR_NOMEM, "arena: cannot grow by %zu MB", cap >> 20);
        return NULL;
    }
    a->cur = a->n - 1;
    a->top = start + bytes;
    if (a->top > a->peak) a->peak = a->top;
    return (float *)a->ch[a->cur].mem;
}

size_t g3d_nn_arena_mark(const g3d_nn_arena *a) { return a->top; }

void g3d_nn_arena_reset(g3d_nn_arena *a, size_t mark)
{
    if (mark > a->top) return;
    a->top = mark;
    while (a->cur > 0 && a->ch[a->cur].start > mark) a->cur--;
    if (mark == 0 && a->n > 1) {
        /* merge into one chunk of the peak size; on failure keep the chunks as they are */
        char *mem = aligned_alloc(64, rup64(a->peak));
        if (!mem) return;
        for (int i = 0; i < a->n; i++) free(a->ch[i].mem);
        a->ch[0] = (chunk){mem, 0, rup64(a->peak)};
        a->n = 1;
        a->cur = 0;
    }
}

size_t g3d_nn_arena_peak(const g3d_nn_arena *a) { return a->peak; }
