/* pickle.c - a restricted unpickler for torch.save's data.pkl.
 *
 * It builds a tree of plain values and never calls anything: the few allowed globals
 * (OrderedDict, torch storage classes, tensor rebuild functions) are recognised by name and
 * their REDUCE is interpreted here. Every other global, opcode or malformed stream is an error.
 */
#include "ckpt_int.h"

#include <stdlib.h>
#include <string.h>

#define PK_MAX_MEMO (1 << 24)
#define PK_MAX_STACK (1 << 24)

typedef struct {
    g3d__pickle *pk;
    const char *label;
    const unsigned char *p, *end;
    g3d__pv **stack; int64_t sp, scap;
    int64_t *marks; int64_t n_marks, mcap;
    g3d__pv **memo; int64_t n_memo, memo_len; /* memo_len: entries stored, MEMOIZE's next index */
    const unsigned char *start;
} pk_state;

static g3d__pv *pv_new(pk_state *st, g3d__pk_kind kind)
{
    g3d__pickle *pk = st->pk;
    if (pk->n_pool == pk->cap_pool) {
        int64_t cap = pk->cap_pool ? pk->cap_pool * 2 : 256;
        g3d__pv **np = realloc(pk->pool, (size_t)cap * sizeof *np);
        if (!np) return NULL;
        pk->pool = np;
        pk->cap_pool = cap;
    }
    g3d__pv *v = calloc(1, sizeof *v);
    if (!v) return NULL;
    v->kind = kind;
    pk->pool[pk->n_pool++] = v;
    return v;
}

static int pv_push_item(g3d__pv *c, g3d__pv *x)
{
    if (c->n == c->cap) {
        int64_t cap = c->cap ? c->cap * 2 : 8;
        g3d__pv **ni = realloc(c->items, (size_t)cap * sizeof *ni);
        if (!ni) return 0;
        c->items = ni;
        c->cap = cap;
    }
    c->items[c->n++] = x;
    return 1;
}

void g3d__pickle_free(g3d__pickle *pk)
{
    for (int64_t i = 0; i < pk->n_pool; i++) {
        free(pk->pool[i]->s);
        free(pk->pool[i]->items);
        free(pk->pool[i]);
    }
    free(pk->pool);
    memset(pk, 0, sizeof *pk);
}

#define PK_FAIL(...) G3D_ERR(G3D_ERR_FORMAT, __VA_ARGS__)

static g3d_status push(pk_state *st, g3d__pv *v)
{
    if (!v) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
    if (st->sp == st->scap) {
        if (st->scap >= PK_MAX_STACK) return PK_FAIL("%s: pickle stack too deep", st->label);
        int64_t cap = st->scap ? st->scap * 2 : 64;
        g3d__pv **ns = realloc(st->stack, (size_t)cap * sizeof *ns);
        if (!ns) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
        st->stack = ns;
        st->scap = cap;
    }
    st->stack[st->sp++] = v;
    return G3D_OK;
}

static g3d_status pop(pk_state *st, g3d__pv **out)
{
    int64_t floor = st->n_marks ? st->marks[st->n_marks - 1] : 0;
    if (st->sp <= floor) return PK_FAIL("%s: pickle stack underflow", st->label);
    *out = st->stack[--st->sp];
    return G3D_OK;
}

/* Pops everything above the last MARK into *first and *count (pointers into the stack, valid until
 * the next push). */
static g3d_status pop_mark(pk_state *st, g3d__pv ***first, int64_t *count)
{
    if (!st->n_marks) return PK_FAIL("%s: pickle MARK expected but missing", st->label);
    int64_t m = st->marks[--st->n_marks];
    *first = st->stack + m;
    *count = st->sp - m;
    st->sp = m;
    return G3D_OK;
}

static int need(pk_state *st, size_t k) { return (size_t)(st->end - st->p) >= k; }

static uint64_t rd_le(const unsigned char *p, int k)
{
    uint64_t v = 0;
    for (int i = k - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

static g3d_status memo_put(pk_state *st, uint64_t idx)
{
    if (st->sp == 0) return PK_FAIL("%s: pickle memo store on an empty stack", st->label);
    if (idx >= PK_MAX_MEMO) return PK_FAIL("%s: pickle memo index %llu too large", st->label, (unsigned long long)idx);
    if ((int64_t)idx >= st->n_memo) {
        int64_t n = st->n_memo ? st->n_memo : 64;
        while (n <= (int64_t)idx) n *= 2;
        g3d__pv **nm = realloc(st->memo, (size_t)n * sizeof *nm);
        if (!nm) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
        memset(nm + st->n_memo, 0, (size_t)(n - st->n_memo) * sizeof *nm);
        st->memo = nm;
        st->n_memo = n;
    }
    if (!st->memo[idx]) st->memo_len++;
    st->memo[idx] = st->stack[st->sp - 1];
    return G3D_OK;
}

static g3d_status memo_get(pk_state *st, uint64_t idx)
{
    if ((int64_t)idx >= st->n_memo || !st->memo[idx])
        return PK_FAIL("%s: pickle refers to unknown memo entry %llu", st->label, (unsigned long long)idx);
    return push(st, st->memo[idx]);
}

static g3d__pv *new_str(pk_state *st, const unsigned char *s, size_t n)
{
    g3d__pv *v = pv_new(st, G3D_PK_STR);
    if (!v) return NULL;
    v->s = malloc(n + 1);
    if (!v->s) return NULL;
    memcpy(v->s, s, n);
    v->s[n] = 0;
    return v;
}

static const struct { const char *name; g3d_dtype dt; } k_storages[] = {
    {"torch.FloatStorage", G3D_DT_F32}, {"torch.HalfStorage", G3D_DT_F16},
    {"torch.BFloat16Storage", G3D_DT_BF16}, {"torch.DoubleStorage", G3D_DT_F64},
    {"torch.LongStorage", G3D_DT_I64}, {"torch.IntStorage", G3D_DT_I32},
    {"torch.ShortStorage", G3D_DT_I16}, {"torch.CharStorage", G3D_DT_I8},
    {"torch.ByteStorage", G3D_DT_U8}, {"torch.BoolStorage", G3D_DT_BOOL},
};

static int storage_dtype(const char *global)
{
    for (size_t i = 0; i < sizeof k_storages / sizeof k_storages[0]; i++)
        if (strcmp(global, k_storages[i].name) == 0) return (int)k_storages[i].dt;
    return -1;
}

static g3d_status make_global(pk_state *st, const char *mod, const char *name)
{
    char full[256];
    snprintf(full, sizeof full, "%s.%s", mod, name);
    if (strcmp(full, "collections.OrderedDict") != 0 && strcmp(full, "torch._utils._rebuild_tensor_v2") != 0 &&
        strcmp(full, "torch._utils._rebuild_parameter") != 0 && storage_dtype(full) < 0)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: unsupported global '%s' in data.pkl", st->label, full);
    g3d__pv *v = new_str(st, (const unsigned char *)full, strlen(full));
    if (v) v->kind = G3D_PK_GLOBAL;
    return push(st, v);
}

static int as_int(const g3d__pv *v, int64_t *out)
{
    if (!v || v->kind != G3D_PK_INT) return 0;
    *out = v->i;
    return 1;
}

/* _rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks[, metadata]) */
static g3d_status rebuild_tensor(pk_state *st, const g3d__pv *args, g3d__pv **out)
{
    if (args->kind != G3D_PK_TUPLE || args->n < 4 || !args->items[0] || args->items[0]->kind != G3D_PK_STORAGE ||
        args->items[2]->kind != G3D_PK_TUPLE || args->items[3]->kind != G3D_PK_TUPLE ||
        args->items[2]->n != args->items[3]->n)
        return PK_FAIL("%s: malformed _rebuild_tensor_v2 arguments", st->label);
    const g3d__pv *size = args->items[2], *stride = args->items[3];
    if (size->n > G3D_MAX_DIMS)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor with %lld dimensions (at most %d supported)", st->label,
                       (long long)size->n, G3D_MAX_DIMS);
    g3d__pv *t = pv_new(st, G3D_PK_TENSOR);
    if (!t) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
    t->storage = args->items[0];
    t->dtype = t->storage->dtype;
    t->ndim = (int)size->n;
    if (!as_int(args->items[1], &t->i) || t->i < 0)
        return PK_FAIL("%s: tensor storage offset is not a non-negative integer", st->label);
    for (int d = 0; d < t->ndim; d++)
        if (!as_int(size->items[d], &t->shape[d]) || !as_int(stride->items[d], &t->stride[d]) || t->shape[d] < 0)
            return PK_FAIL("%s: tensor size/stride entries must be non-negative integers", st->label);
    *out = t;
    return G3D_OK;
}

static g3d_status do_reduce(pk_state *st)
{
    g3d__pv *args = NULL, *fn = NULL, *res = NULL;
    G3D_TRY(pop(st, &args));
    G3D_TRY(pop(st, &fn));
    if (fn->kind != G3D_PK_GLOBAL || args->kind != G3D_PK_TUPLE)
        return PK_FAIL("%s: REDUCE needs a global and an argument tuple", st->label);
    if (strcmp(fn->s, "collections.OrderedDict") == 0) {
        if (args->n != 0) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: OrderedDict with constructor arguments", st->label);
        res = pv_new(st, G3D_PK_DICT);
    } else if (strcmp(fn->s, "torch._utils._rebuild_tensor_v2") == 0) {
        G3D_TRY(rebuild_tensor(st, args, &res));
    } else if (strcmp(fn->s, "torch._utils._rebuild_parameter") == 0) {
        if (args->n < 1 || args->items[0]->kind != G3D_PK_TENSOR)
            return PK_FAIL("%s: malformed _rebuild_parameter arguments", st->label);
        res = args->items[0];
    } else {
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: cannot call '%s' in data.pkl", st->label, fn->s);
    }
    return push(st, res);
}

/* Persistent id ('storage', StorageClass, key, location, numel). */
static g3d_status do_persid(pk_state *st)
{
    g3d__pv *pid = NULL;
    G3D_TRY(pop(st, &pid));
    int64_t numel;
    if (pid->kind != G3D_PK_TUPLE || pid->n != 5 || pid->items[0]->kind != G3D_PK_STR ||
        strcmp(pid->items[0]->s, "storage") != 0 || pid->items[1]->kind != G3D_PK_GLOBAL ||
        pid->items[2]->kind != G3D_PK_STR || !as_int(pid->items[4], &numel) || numel < 0)
        return PK_FAIL("%s: unsupported persistent id (expected ('storage', type, key, location, numel))", st->label);
    int dt = storage_dtype(pid->items[1]->s);
    if (dt < 0) return PK_FAIL("%s: persistent id names '%s', not a storage class", st->label, pid->items[1]->s);
    g3d__pv *v = new_str(st, (const unsigned char *)pid->items[2]->s, strlen(pid->items[2]->s));
    if (v) { v->kind = G3D_PK_STORAGE; v->dtype = dt; v->i = numel; }
    return push(st, v);
}

static g3d_status make_seq(pk_state *st, g3d__pk_kind kind, g3d__pv **items, int64_t n)
{
    g3d__pv *t = pv_new(st, kind);
    if (!t) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
    for (int64_t i = 0; i < n; i++)
        if (!pv_push_item(t, items[i])) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
    return push(st, t);
}

static g3d_status add_items(pk_state *st, g3d__pv *c, g3d__pv **items, int64_t n, int dict)
{
    if (dict ? c->kind != G3D_PK_DICT : c->kind != G3D_PK_LIST)
        return PK_FAIL("%s: %s applied to a non-%s", st->label, dict ? "SETITEM" : "APPEND", dict ? "dict" : "list");
    if (dict && n % 2) return PK_FAIL("%s: SETITEMS with an odd number of items", st->label);
    for (int64_t i = 0; i < n; i++)
        if (!pv_push_item(c, items[i])) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
    return G3D_OK;
}

static g3d_status run(pk_state *st)
{
    g3d__pv *a = NULL, *b = NULL, *c = NULL, **items = NULL;
    int64_t n = 0;
    while (st->p < st->end) {
        unsigned char op = *st->p++;
        switch (op) {
        case 0x80: /* PROTO */
            if (!need(st, 1)) goto truncated;
            if (st->p[0] < 2 || st->p[0] > 5) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: pickle protocol %d", st->label, st->p[0]);
            st->p++;
            break;
        case 0x95: /* FRAME: a length hint only */
            if (!need(st, 8)) goto truncated;
            st->p += 8;
            break;
        case '}': G3D_TRY(push(st, pv_new(st, G3D_PK_DICT))); break;
        case ']': G3D_TRY(push(st, pv_new(st, G3D_PK_LIST))); break;
        case ')': G3D_TRY(push(st, pv_new(st, G3D_PK_TUPLE))); break;
        case 'N': G3D_TRY(push(st, pv_new(st, G3D_PK_NONE))); break;
        case 0x88: case 0x89:
            a = pv_new(st, G3D_PK_BOOL);
            if (a) a->i = op == 0x88;
            G3D_TRY(push(st, a));
            break;
        case '(':
            if (st->n_marks == st->mcap) {
                int64_t cap = st->mcap ? st->mcap * 2 : 16;
                if (cap > PK_MAX_STACK) return PK_FAIL("%s: too many pickle MARKs", st->label);
                int64_t *nm = realloc(st->marks, (size_t)cap * sizeof *nm);
                if (!nm) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory while unpickling", st->label);
                st->marks = nm;
                st->mcap = cap;
            }
            st->marks[st->n_marks++] = st->sp;
            break;
        case 'X': case 0x8c: { /* BINUNICODE, SHORT_BINUNICODE */
            int k = op == 'X' ? 4 : 1;
            if (!need(st, (size_t)k)) goto truncated;
            uint64_t len = rd_le(st->p, k);
            st->p += k;
            if (!need(st, len)) goto truncated;
            G3D_TRY(push(st, new_str(st, st->p, (size_t)len)));
            st->p += len;
            break;
        }
        case 'J': case 'K': case 'M': { /* BININT, BININT1, BININT2 */
            int k = op == 'J' ? 4 : op == 'K' ? 1 : 2;
            if (!need(st, (size_t)k)) goto truncated;
            a = pv_new(st, G3D_PK_INT);
            if (a) a->i = op == 'J' ? (int64_t)(int32_t)(uint32_t)rd_le(st->p, 4) : (int64_t)rd_le(st->p, k);
            st->p += k;
            G3D_TRY(push(st, a));
            break;
        }
        case 0x8a: { /* LONG1: little-endian two's complement */
            if (!need(st, 1)) goto truncated;
            int k = st->p[0];
            st->p++;
            if (!need(st, (size_t)k)) goto truncated;
            if (k > 8) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: pickled integer of %d bytes", st->label, k);
            uint64_t u = k ? rd_le(st->p, k) : 0;
            if (k && k < 8 && (st->p[k - 1] & 0x80)) u |= ~0ull << (8 * k);
            st->p += k;
            a = pv_new(st, G3D_PK_INT);
            if (a) a->i = (int64_t)u;
            G3D_TRY(push(st, a));
            break;
        }
        case 'G': { /* BINFLOAT: big-endian double */
            if (!need(st, 8)) goto truncated;
            uint64_t u = 0;
            for (int i = 0; i < 8; i++) u = (u << 8) | st->p[i];
            st->p += 8;
            a = pv_new(st, G3D_PK_FLOAT);
            if (a) memcpy(&a->f, &u, 8);
            G3D_TRY(push(st, a));
            break;
        }
        case 't': G3D_TRY(pop_mark(st, &items, &n)); G3D_TRY(make_seq(st, G3D_PK_TUPLE, items, n)); break;
        case 0x85: case 0x86: case 0x87: { /* TUPLE1..3 */
            int k = op - 0x84;
            int64_t floor = st->n_marks ? st->marks[st->n_marks - 1] : 0;
            if (st->sp - floor < k) return PK_FAIL("%s: pickle stack underflow", st->label);
            st->sp -= k;
            G3D_TRY(make_seq(st, G3D_PK_TUPLE, st->stack + st->sp, k));
            break;
        }
        case 's':
            G3D_TRY(pop(st, &b)); G3D_TRY(pop(st, &a)); G3D_TRY(pop(st, &c));
            {
                g3d__pv *kv[2] = {a, b};
                G3D_TRY(add_items(st, c, kv, 2, 1));
            }
            G3D_TRY(push(st, c));
            break;
        case 'u': case 'e':
            G3D_TRY(pop_mark(st, &items, &n));
            {
                /* items stay valid: the container is below them and nothing is pushed yet. */
                g3d__pv **tmp = items;
                G3D_TRY(pop(st, &c));
                G3D_TRY(add_items(st, c, tmp, n, op == 'u'));
                G3D_TRY(push(st, c));
            }
            break;
        case 'a':
            G3D_TRY(pop(st, &b)); G3D_TRY(pop(st, &c));
            G3D_TRY(add_items(st, c, &b, 1, 0));
            G3D_TRY(push(st, c));
            break;
        case 'q': if (!need(st, 1)) goto truncated; G3D_TRY(memo_put(st, st->p[0])); st->p += 1; break;
        case 'r': if (!need(st, 4)) goto truncated; G3D_TRY(memo_put(st, rd_le(st->p, 4))); st->p += 4; break;
        case 0x94: G3D_TRY(memo_put(st, (uint64_t)st->memo_len)); break;
        case 'h': if (!need(st, 1)) goto truncated; G3D_TRY(memo_get(st, st->p[0])); st->p += 1; break;
        case 'j': if (!need(st, 4)) goto truncated; G3D_TRY(memo_get(st, rd_le(st->p, 4))); st->p += 4; break;
        case 'c': { /* GLOBAL "module\nname\n" */
            const unsigned char *nl1 = memchr(st->p, '\n', (size_t)(st->end - st->p));
            if (!nl1) goto truncated;
            const unsigned char *nl2 = memchr(nl1 + 1, '\n', (size_t)(st->end - nl1 - 1));
            if (!nl2) goto truncated;
            char mod[128], name[128];
            if (nl1 - st->p >= (long)sizeof mod || nl2 - nl1 - 1 >= (long)sizeof name)
                return PK_FAIL("%s: pickle GLOBAL name too long", st->label);
            memcpy(mod, st->p, (size_t)(nl1 - st->p));
            mod[nl1 - st->p] = 0;
            memcpy(name, nl1 + 1, (size_t)(nl2 - nl1 - 1));
            name[nl2 - nl1 - 1] = 0;
            st->p = nl2 + 1;
            G3D_TRY(make_global(st, mod, name));
            break;
        }
        case 0x93: /* STACK_GLOBAL */
            G3D_TRY(pop(st, &b)); G3D_TRY(pop(st, &a));
            if (a->kind != G3D_PK_STR || b->kind != G3D_PK_STR)
                return PK_FAIL("%s: STACK_GLOBAL needs two strings", st->label);
            G3D_TRY(make_global(st, a->s, b->s));
            break;
        case 'R': G3D_TRY(do_reduce(st)); break;
        case 'b': /* BUILD: object state (e.g. a state dict's _metadata) carries no tensors we need */
            G3D_TRY(pop(st, &b));
            if (st->sp == 0) return PK_FAIL("%s: pickle stack underflow", st->label);
            break;
        case 'Q': G3D_TRY(do_persid(st)); break;
        case '.':
            G3D_TRY(pop(st, &st->pk->root));
            return G3D_OK;
        default:
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: unsupported pickle opcode 0x%02x at byte %ld", st->label, op,
                           (long)(st->p - 1 - st->start));
        }
    }
truncated:
    return PK_FAIL("%s: truncated pickle stream", st->label);
}

g3d_status g3d__pickle_load(g3d__pickle *pk, const unsigned char *buf, size_t n, const char *label)
{
    memset(pk, 0, sizeof *pk);
    pk_state st;
    memset(&st, 0, sizeof st);
    st.pk = pk;
    st.label = label;
    st.p = buf;
    st.start = buf;
    st.end = buf + n;
    g3d_status rc = run(&st);
    free(st.stack);
    free(st.marks);
    free(st.memo);
    return rc;
}
