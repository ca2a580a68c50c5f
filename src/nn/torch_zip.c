/* PyTorch zip checkpoints (torch.save since 1.6): <archive>/data.pkl, a pickle of the saved
 * object whose tensors refer to raw storages <archive>/data/<key>. The pickle is read by a
 * restricted machine that knows only the opcodes torch.save emits and rebuilds only tensors,
 * plain containers and ordered dicts; nothing is ever executed. Other classes (a training
 * framework's callbacks, configuration objects) become opaque placeholders, provided they hold
 * no tensors; calls into modules that reach the system are refused outright. */
#include "ckpt_int.h"
#include "gen3d/zip.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_PICKLE_BYTES ((uint64_t)256 << 20)
#define MAX_VALUES 50000000

/* V_OPAQUE: an instance of a class the reader does not know, kept only by its name. */
typedef enum { V_NONE, V_BOOL, V_INT, V_FLOAT, V_STR, V_TUPLE, V_LIST, V_DICT, V_GLOBAL, V_STORAGE, V_TENSOR, V_OPAQUE, V_MARK } vkind;

/* Globals: the ones rebuilt, any other class (instances become V_OPAQUE), and callables that
 * are refused when called (modules that reach the file system, processes or the interpreter). */
typedef enum { G_ORDERED_DICT, G_REBUILD_TENSOR, G_REBUILD_PARAMETER, G_STORAGE, G_OPAQUE, G_REFUSED } gkind;

typedef struct value value;
struct value {
    vkind kind;
    int64_t i;            /* int, bool; global: gkind; storage: numel */
    double f;
    char *s;              /* str; storage: key; global, opaque: "module.name" */
    value **items;        /* tuple/list items; dict: key, value pairs */
    int64_t n, cap;
    g3d_dtype dtype;      /* global storage type, storage, tensor */
    value *storage;       /* tensor */
    int64_t offset, ndim, shape[G3D_MAX_DIMS], stride[G3D_MAX_DIMS];
};

typedef struct unpickler {
    const char *label;
    const unsigned char *p, *end;
    value **stack;
    int64_t sp, stack_cap;
    value **memo;
    int64_t memo_cap;
    value **all;          /* every value allocated, for freeing */
    int64_t nall, all_cap;
    int64_t scan_left;    /* values that tensor checks of opaque objects may still visit */
} unpickler;

static value *new_value(unpickler *u, vkind k)
{
    if (u->nall >= MAX_VALUES) return NULL;
    if (u->nall == u->all_cap) {
        int64_t cap = u->all_cap ? 2 * u->all_cap : 256;
        value **a = realloc(u->all, sizeof(value *) * (size_t)cap);
        if (!a) return NULL;
        u->all = a;
        u->all_cap = cap;
    }
    value *v = calloc(1, sizeof *v);
    if (!v) return NULL;
    v->kind = k;
    u->all[u->nall++] = v;
    return v;
}

static void unpickler_free(unpickler *u)
{
    for (int64_t i = 0; i < u->nall; i++) { free(u->all[i]->s); free(u->all[i]->items); free(u->all[i]); }
    free(u->all);
    free(u->stack);
    free(u->memo);
}

static int append_item(value *c, value *v)
{
    if (c->n == c->cap) {
        int64_t cap = c->cap ? 2 * c->cap : 8;
        value **a = realloc(c->items, sizeof(value *) * (size_t)cap);
        if (!a) return 0;
        c->items = a;
        c->cap = cap;
    }
    c->items[c->n++] = v;
    return 1;
}

static int push(unpickler *u, value *v)
{
    if (!v) return 0;
    if (u->sp == u->stack_cap) {
        int64_t cap = u->stack_cap ? 2 * u->stack_cap : 64;
        value **a = realloc(u->stack, sizeof(value *) * (size_t)cap);
        if (!a) return 0;
        u->stack = a;
        u->stack_cap = cap;
    }
    u->stack[u->sp++] = v;
    return 1;
}

/* Index of the topmost mark, or -1. */
static int64_t find_mark(const unpickler *u)
{
    for (int64_t i = u->sp - 1; i >= 0; i--)
        if (u->stack[i]->kind == V_MARK) return i;
    return -1;
}

static int need(const unpickler *u, size_t n) { return (size_t)(u->end - u->p) >= n; }

static uint64_t le(const unsigned char *p, int n)
{
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

static const struct { const char *module, *name; gkind kind; g3d_dtype dtype; } g_globals[] = {
    {"collections", "OrderedDict", G_ORDERED_DICT, G3D_DT_F32},
    {"torch._utils", "_rebuild_tensor_v2", G_REBUILD_TENSOR, G3D_DT_F32},
    {"torch._utils", "_rebuild_parameter", G_REBUILD_PARAMETER, G3D_DT_F32},
    {"torch", "FloatStorage", G_STORAGE, G3D_DT_F32},
    {"torch", "HalfStorage", G_STORAGE, G3D_DT_F16},
    {"torch", "BFloat16Storage", G_STORAGE, G3D_DT_BF16},
    {"torch", "DoubleStorage", G_STORAGE, G3D_DT_F64},
    {"torch", "LongStorage", G_STORAGE, G3D_DT_I64},
    {"torch", "IntStorage", G_STORAGE, G3D_DT_I32},
    {"torch", "ShortStorage", G_STORAGE, G3D_DT_I16},
    {"torch", "CharStorage", G_STORAGE, G3D_DT_I8},
    {"torch", "ByteStorage", G_STORAGE, G3D_DT_U8},
    {"torch", "BoolStorage", G_STORAGE, G3D_DT_BOOL},
};

/* Modules whose callables act on the system or the interpreter, and torch itself (a torch call
 * other than those above would rebuild a tensor this reader cannot place). Nothing is ever
 * called, but a checkpoint that asks for one of these is hostile or unreadable: refused. */
static const char *const g_refused_modules[] = {"os", "posix", "nt", "sys", "subprocess", "shutil", "importlib",
                                                "runpy", "code", "codeop", "ctypes", "socket", "pickle", "_pickle",
                                                "marshal", "pty", "webbrowser", "io", "_io", "tempfile", "signal",
                                                "multiprocessing", "threading", "asyncio", "glob",
                                                "builtins", "__builtin__", "torch"};
/* Builtin types whose instances are plain data. */
static const char *const g_builtin_types[] = {"set", "frozenset", "bytearray", "bytes", "complex", "slice", "range",
                                              "object"};

static int refused_call(const char *module, const char *name)
{
    size_t top = strcspn(module, ".");
    int builtin = !strcmp(module, "builtins") || !strcmp(module, "__builtin__");
    for (size_t k = 0; builtin && k < sizeof g_builtin_types / sizeof *g_builtin_types; k++)
        if (!strcmp(name, g_builtin_types[k])) return 0;
    for (size_t k = 0; k < sizeof g_refused_modules / sizeof *g_refused_modules; k++)
        if (strlen(g_refused_modules[k]) == top && !strncmp(module, g_refused_modules[k], top)) return 1;
    return 0;
}

/* Pushes a global. Referring to any global is harmless (it is only a name); what a call of it
 * gives is decided in reduce() and newobj(). */
static g3d_status make_global(unpickler *u, const char *module, const char *name)
{
    value *v = new_value(u, V_GLOBAL);
    size_t n = strlen(module) + strlen(name) + 2;
    if (!v || !(v->s = malloc(n))) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
    snprintf(v->s, n, "%s.%s", module, name);
    v->i = refused_call(module, name) ? G_REFUSED : G_OPAQUE;
    for (size_t k = 0; k < sizeof g_globals / sizeof *g_globals; k++)
        if (!strcmp(module, g_globals[k].module) && !strcmp(name, g_globals[k].name)) {
            v->i = g_globals[k].kind;
            v->dtype = g_globals[k].dtype;
        }
    return push(u, v) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
}

#define SCAN_MAX_DEPTH 64

/* 1 if v holds a tensor or a storage (or is too deep or too large to tell: the scans of one
 * pickle share a budget, so that repeated references cannot make them quadratic). */
static int carries_tensor(unpickler *u, const value *v, int depth)
{
    if (depth >= SCAN_MAX_DEPTH || --u->scan_left < 0) return 1;
    if (v->kind == V_TENSOR || v->kind == V_STORAGE) return 1;
    if (v->kind == V_DICT || v->kind == V_LIST || v->kind == V_TUPLE)
        for (int64_t k = 0; k < v->n; k++)
            if (carries_tensor(u, v->items[k], depth + 1)) return 1;
    return 0;
}

/* A tensor inside an object the reader does not know could not be named. */
static g3d_status tensor_in_opaque(const unpickler *u, const value *cls)
{
    return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl keeps tensors inside a '%s' object (or nests too deeply); "
                   "only tensors in plain containers are loaded", u->label, cls->s);
}

/* An instance of the opaque class `cls`, built from `data` (arguments or state, NULL for none)
 * that must carry no tensor. */
static g3d_status make_opaque(unpickler *u, const value *cls, const value *data, value **out)
{
    if (data && carries_tensor(u, data, 0)) return tensor_in_opaque(u, cls);
    value *r = new_value(u, V_OPAQUE);
    size_t n = strlen(cls->s) + 1;
    if (!r || !(r->s = malloc(n))) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
    memcpy(r->s, cls->s, n);
    *out = r;
    return G3D_OK;
}

static g3d_status refuse_global(const unpickler *u, const value *fn)
{
    return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl uses the global '%s', which a checkpoint reader will not load",
                   u->label, fn->s);
}

static int64_t tuple_int(const value *t, int64_t i, int *ok)
{
    if (t->kind != V_TUPLE || i >= t->n || t->items[i]->kind != V_INT) { *ok = 0; return 0; }
    return t->items[i]->i;
}

/* REDUCE: calls one of the accepted globals with an argument tuple. */
static g3d_status reduce(unpickler *u, value *fn, value *args)
{
    if (fn->kind != V_GLOBAL || args->kind != V_TUPLE) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed call", u->label);
    value *r = NULL;
    if (fn->i == G_REFUSED) return refuse_global(u, fn);
    if (fn->i == G_ORDERED_DICT) {
        r = new_value(u, V_DICT);
    } else if (fn->i == G_OPAQUE) {
        G3D_TRY(make_opaque(u, fn, args, &r));
    } else if (fn->i == G_REBUILD_PARAMETER) {
        if (args->n < 1 || args->items[0]->kind != V_TENSOR) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed parameter", u->label);
        r = args->items[0];
    } else if (fn->i == G_REBUILD_TENSOR) {
        /* (storage, storage_offset, size, stride, requires_grad, backward_hooks[, metadata]) */
        int ok = 1;
        if (args->n < 4 || args->items[0]->kind != V_STORAGE || args->items[1]->kind != V_INT ||
            args->items[2]->kind != V_TUPLE || args->items[3]->kind != V_TUPLE || args->items[2]->n != args->items[3]->n ||
            args->items[2]->n > G3D_MAX_DIMS)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed tensor", u->label);
        r = new_value(u, V_TENSOR);
        if (!r) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
        r->storage = args->items[0];
        r->dtype = r->storage->dtype;
        r->offset = args->items[1]->i;
        r->ndim = args->items[2]->n;
        for (int64_t k = 0; k < r->ndim; k++) {
            r->shape[k] = tuple_int(args->items[2], k, &ok);
            r->stride[k] = tuple_int(args->items[3], k, &ok);
        }
        if (!ok) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed tensor size or stride", u->label);
    } else {
        return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: a storage type cannot be called", u->label);
    }
    if (!r || !push(u, r)) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
    return G3D_OK;
}

/* NEWOBJ / NEWOBJ_EX: cls.__new__(cls, *args, **kwargs) (kwargs NULL for NEWOBJ). */
static g3d_status newobj(unpickler *u, value *cls, value *args, value *kwargs)
{
    if (cls->kind != V_GLOBAL || args->kind != V_TUPLE || (kwargs && kwargs->kind != V_DICT))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed object creation", u->label);
    value *r = NULL;
    if (cls->i == G_ORDERED_DICT) {
        r = new_value(u, V_DICT);
    } else if (cls->i == G_OPAQUE) {
        if (kwargs && carries_tensor(u, kwargs, 0)) return tensor_in_opaque(u, cls);
        G3D_TRY(make_opaque(u, cls, args, &r));
    } else {
        return cls->i == G_REFUSED ? refuse_global(u, cls) : G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: '%s' is not a class", u->label, cls->s);
    }
    if (!r || !push(u, r)) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
    return G3D_OK;
}

static g3d_status run_pickle(unpickler *u, value **result)
{
    g3d_status rc = G3D_OK;
#define NEED(n) do { if (!need(u, (n))) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl is truncated", u->label); } while (0)
#define POP(v) do { if (u->sp < 1 || u->stack[u->sp - 1]->kind == V_MARK) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: stack underflow", u->label); (v) = u->stack[--u->sp]; } while (0)
#define PUSH(v) do { if (!push(u, (v))) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label); } while (0)
    while (1) {
        NEED(1);
        unsigned char op = *u->p++;
        value *v = NULL, *a = NULL, *b = NULL;
        switch (op) {
        case 0x80: NEED(1); if (*u->p > 5) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: pickle protocol %d", u->label, *u->p); u->p++; break;
        case 0x95: NEED(8); u->p += 8; break; /* FRAME: a length hint */
        case '.': /* STOP */
            if (u->sp != 1) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl ends with %lld values on the stack", u->label, (long long)u->sp);
            *result = u->stack[0];
            return G3D_OK;
        case '}': PUSH(new_value(u, V_DICT)); break;
        case ']': PUSH(new_value(u, V_LIST)); break;
        case ')': PUSH(new_value(u, V_TUPLE)); break;
        case '(': PUSH(new_value(u, V_MARK)); break;
        case 'N': PUSH(new_value(u, V_NONE)); break;
        case 0x88: case 0x89: v = new_value(u, V_BOOL); if (v) v->i = op == 0x88; PUSH(v); break;
        case 'J': NEED(4); v = new_value(u, V_INT); if (v) v->i = (int32_t)le(u->p, 4); u->p += 4; PUSH(v); break;
        case 'K': NEED(1); v = new_value(u, V_INT); if (v) v->i = *u->p; u->p += 1; PUSH(v); break;
        case 'M': NEED(2); v = new_value(u, V_INT); if (v) v->i = (int64_t)le(u->p, 2); u->p += 2; PUSH(v); break;
        case 0x8a: { /* LONG1: little-endian two's complement of n bytes */
            NEED(1);
            int n = *u->p++;
            NEED((size_t)n);
            if (n > 8) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl: integer of %d bytes", u->label, n);
            uint64_t x = n ? le(u->p, n) : 0;
            if (n && n < 8 && (u->p[n - 1] & 0x80)) x |= ~(uint64_t)0 << (8 * n);
            u->p += n;
            v = new_value(u, V_INT);
            if (v) v->i = (int64_t)x;
            PUSH(v);
            break;
        }
        case 'G': { /* BINFLOAT: big-endian double */
            NEED(8);
            uint64_t x = 0;
            for (int k = 0; k < 8; k++) x = (x << 8) | u->p[k];
            u->p += 8;
            v = new_value(u, V_FLOAT);
            if (v) memcpy(&v->f, &x, 8);
            PUSH(v);
            break;
        }
        case 'X': case 0x8c: case 0x8d: { /* BINUNICODE, SHORT_BINUNICODE, BINUNICODE8 */
            int w = op == 'X' ? 4 : op == 0x8c ? 1 : 8;
            NEED((size_t)w);
            uint64_t n = le(u->p, w);
            u->p += w;
            if (n > (uint64_t)(u->end - u->p)) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl is truncated", u->label);
            v = new_value(u, V_STR);
            if (v && (v->s = malloc((size_t)n + 1))) { memcpy(v->s, u->p, (size_t)n); v->s[n] = 0; }
            if (!v || !v->s) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
            u->p += n;
            PUSH(v);
            break;
        }
        case 't': case 'l': { /* TUPLE / LIST from the topmost mark */
            int64_t m = find_mark(u);
            if (m < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: no mark for a tuple", u->label);
            v = new_value(u, op == 't' ? V_TUPLE : V_LIST);
            if (!v) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
            for (int64_t k = m + 1; k < u->sp; k++) if (!append_item(v, u->stack[k])) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            u->sp = m;
            PUSH(v);
            break;
        }
        case 0x85: case 0x86: case 0x87: { /* TUPLE1..3 */
            int n = op - 0x84;
            if (find_mark(u) >= u->sp - n || u->sp < n) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: stack underflow", u->label);
            v = new_value(u, V_TUPLE);
            if (!v) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", u->label);
            for (int64_t k = u->sp - n; k < u->sp; k++) if (!append_item(v, u->stack[k])) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            u->sp -= n;
            PUSH(v);
            break;
        }
        case 's': case 'u': case 'a': case 'e': { /* SETITEM(S), APPEND(S) */
            int64_t lo, target, m = find_mark(u);
            if (op == 's' || op == 'a') {
                lo = u->sp - (op == 's' ? 2 : 1);
                target = lo - 1;
                if (target < 0 || m >= target) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: stack underflow", u->label);
            } else {
                if (m < 1) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: items without a mark", u->label);
                lo = m + 1;
                target = m - 1;
            }
            value *c = u->stack[target];
            int is_dict = op == 's' || op == 'u';
            if ((c->kind != (is_dict ? V_DICT : V_LIST) && c->kind != V_OPAQUE) || (is_dict && (u->sp - lo) % 2))
                return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: items added to a %s", u->label, is_dict ? "non-dict" : "non-list");
            for (int64_t k = lo; k < u->sp; k++) {
                if (u->stack[k]->kind == V_MARK) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: misplaced mark", u->label);
                /* a dict or list subclass the reader does not know: its items are dropped */
                if (c->kind == V_OPAQUE) {
                    if (carries_tensor(u, u->stack[k], 0)) return tensor_in_opaque(u, c);
                } else if (!append_item(c, u->stack[k])) {
                    return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
                }
            }
            u->sp = target + 1;
            break;
        }
        case 'q': case 'r': case 0x94: { /* BINPUT, LONG_BINPUT, MEMOIZE */
            int64_t idx;
            if (op == 0x94) idx = -1;
            else { int w = op == 'q' ? 1 : 4; NEED((size_t)w); idx = (int64_t)le(u->p, w); u->p += w; }
            if (u->sp < 1) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: stack underflow", u->label);
            if (idx < 0) { /* MEMOIZE: the next free slot */
                idx = 0;
                while (idx < u->memo_cap && u->memo[idx]) idx++;
            }
            if (idx > MAX_VALUES) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: memo index %lld", u->label, (long long)idx);
            if (idx >= u->memo_cap) {
                int64_t cap = u->memo_cap ? u->memo_cap : 64;
                while (cap <= idx) cap *= 2;
                value **m = realloc(u->memo, sizeof(value *) * (size_t)cap);
                if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
                memset(m + u->memo_cap, 0, sizeof(value *) * (size_t)(cap - u->memo_cap));
                u->memo = m;
                u->memo_cap = cap;
            }
            u->memo[idx] = u->stack[u->sp - 1];
            break;
        }
        case 'h': case 'j': { /* BINGET, LONG_BINGET */
            int w = op == 'h' ? 1 : 4;
            NEED((size_t)w);
            int64_t idx = (int64_t)le(u->p, w);
            u->p += w;
            if (idx >= u->memo_cap || !u->memo[idx]) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: memo entry %lld is unset", u->label, (long long)idx);
            PUSH(u->memo[idx]);
            break;
        }
        case 'c': { /* GLOBAL "module\nname\n" */
            char mod[128], name[128];
            for (int part = 0; part < 2; part++) {
                char *dst = part ? name : mod;
                int k = 0;
                while (u->p < u->end && *u->p != '\n' && k < 127) dst[k++] = (char)*u->p++;
                if (u->p >= u->end || *u->p != '\n') return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed global", u->label);
                u->p++;
                dst[k] = 0;
            }
            if ((rc = make_global(u, mod, name)) != G3D_OK) return rc;
            break;
        }
        case 0x93: /* STACK_GLOBAL */
            POP(b);
            POP(a);
            if (a->kind != V_STR || b->kind != V_STR) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed global", u->label);
            if ((rc = make_global(u, a->s, b->s)) != G3D_OK) return rc;
            break;
        case 'R': POP(b); POP(a); if ((rc = reduce(u, a, b)) != G3D_OK) return rc; break;
        case 0x81: POP(b); POP(a); if ((rc = newobj(u, a, b, NULL)) != G3D_OK) return rc; break; /* NEWOBJ */
        case 0x92: { /* NEWOBJ_EX */
            value *c;
            POP(c); POP(b); POP(a);
            if ((rc = newobj(u, a, b, c)) != G3D_OK) return rc;
            break;
        }
        case 'b': /* BUILD: state for an object; our dicts take none that matters (e.g. _metadata),
                   * an opaque object's is dropped once it is known to hold no tensor */
            POP(b);
            if (u->sp < 1 || (u->stack[u->sp - 1]->kind != V_DICT && u->stack[u->sp - 1]->kind != V_OPAQUE))
                return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: state for an unsupported object", u->label);
            if (u->stack[u->sp - 1]->kind == V_OPAQUE && carries_tensor(u, b, 0))
                return tensor_in_opaque(u, u->stack[u->sp - 1]);
            break;
        case 'Q': { /* BINPERSID: ('storage', storage type, key, location, numel) */
            POP(a);
            int ok = 1;
            if (a->kind != V_TUPLE || a->n != 5 || a->items[0]->kind != V_STR || strcmp(a->items[0]->s, "storage") ||
                a->items[1]->kind != V_GLOBAL || a->items[1]->i != G_STORAGE || a->items[2]->kind != V_STR)
                ok = 0;
            int64_t numel = ok ? tuple_int(a, 4, &ok) : 0;
            if (!ok || numel < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl: malformed storage reference", u->label);
            v = new_value(u, V_STORAGE);
            if (!v || !(v->s = malloc(strlen(a->items[2]->s) + 1))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            strcpy(v->s, a->items[2]->s);
            v->dtype = a->items[1]->dtype;
            v->i = numel;
            PUSH(v);
            break;
        }
        default:
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl uses pickle opcode 0x%02x, which a checkpoint reader does not accept", u->label, op);
        }
    }
#undef NEED
#undef POP
#undef PUSH
}

/* ---- from the unpickled object to the checkpoint index ----------------------------------- */

typedef struct walk {
    g3d_ckpt *ck;
    const g3d_zip *zip;
    const char *prefix;   /* archive folder, e.g. "state" */
    int64_t cap;
    int depth;            /* nesting of the value being walked */
    int64_t visits;       /* values walked so far */
} walk;

/* A memoised container can hold itself, and shared references can make a tiny pickle describe
 * a huge tree: bound both the nesting and the number of values visited. */
#define WALK_MAX_DEPTH 64
#define WALK_MAX_VISITS (1 << 20)

static g3d_status add_tensor(walk *w, const char *name, const value *t)
{
    g3d_ckpt *ck = w->ck;
    const value *st = t->storage;
    char entry[512];
    snprintf(entry, sizeof entry, "%s/data/%s", w->prefix, st->s);
    int64_t zi = g3d_zip_find(w->zip, entry);
    if (zi < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' refers to a storage '%s' that is not in the archive", ck->path, name, entry);
    const unsigned char *data = g3d_zip_stored_data(w->zip, zi);
    if (!data) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: storage '%s' is compressed; torch.save writes it uncompressed", ck->path, entry);
    size_t es = g3d_dtype_size(st->dtype);
    uint64_t bytes = w->zip->entries[zi].size;
    if ((uint64_t)st->i > bytes / es) return G3D_ERR(G3D_ERR_FORMAT, "%s: storage '%s' is shorter than declared", ck->path, entry);
    /* Contiguous row-major only: the stride of each dimension is the product of the sizes after it. */
    int64_t numel = 1, expect = 1;
    for (int64_t k = t->ndim - 1; k >= 0; k--) {
        if (t->shape[k] < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' has a negative size", ck->path, name);
        if (t->shape[k] > 1 && t->stride[k] != expect)
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor '%s' is not contiguous (save it with .contiguous())", ck->path, name);
        if (t->shape[k] && expect > ((int64_t)1 << 40) / t->shape[k]) return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' is absurdly large", ck->path, name);
        expect *= t->shape[k];
    }
    numel = expect;
    if (t->offset < 0 || t->offset > st->i || numel > st->i - t->offset)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' reaches past the end of its storage", ck->path, name);
    if (ck->n == w->cap) {
        int64_t cap = w->cap ? 2 * w->cap : 64;
        g3d_tensor_info *a = realloc(ck->tensors, sizeof *a * (size_t)cap);
        if (!a) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        ck->tensors = a;
        w->cap = cap;
    }
    g3d_tensor_info *ti = &ck->tensors[ck->n];
    memset(ti, 0, sizeof *ti);
    char *copy = malloc(strlen(name) + 1);
    if (!copy) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    strcpy(copy, name);
    ti->name = copy;
    ti->dtype = st->dtype;
    ti->ndim = (int)t->ndim;
    memcpy(ti->shape, t->shape, sizeof(int64_t) * (size_t)t->ndim);
    ti->numel = numel;
    ti->data = data + (size_t)t->offset * es;
    ck->n++;
    return G3D_OK;
}

/* Walks the object: tensors are indexed under their dotted path; everything else becomes JSON
 * with tensors replaced by their names. */
static g3d_status walk_children(walk *w, const value *v, const char *path, char *sub, cJSON **json);

static g3d_status walk_value(walk *w, const value *v, const char *path, cJSON **json)
{
    char sub[1024];
    *json = NULL;
    if (w->depth >= WALK_MAX_DEPTH || ++w->visits > WALK_MAX_VISITS)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl nests deeper than %d levels, refers to itself, or is too large",
                       w->ck->path, WALK_MAX_DEPTH);
    w->depth++;
    g3d_status rc = walk_children(w, v, path, sub, json);
    w->depth--;
    return rc;
}

static g3d_status walk_children(walk *w, const value *v, const char *path, char *sub, cJSON **json)
{
    switch (v->kind) {
    case V_NONE: *json = cJSON_CreateNull(); break;
    case V_BOOL: *json = cJSON_CreateBool((int)v->i); break;
    case V_INT: *json = cJSON_CreateNumber((double)v->i); break;
    case V_FLOAT: *json = cJSON_CreateNumber(v->f); break;
    case V_STR: *json = cJSON_CreateString(v->s); break;
    case V_GLOBAL: case V_OPAQUE: *json = cJSON_CreateString(v->s); break; /* by name only */
    case V_TENSOR:
        G3D_TRY(add_tensor(w, path, v));
        *json = cJSON_CreateString(path);
        break;
    case V_TUPLE:
    case V_LIST:
        *json = cJSON_CreateArray();
        for (int64_t k = 0; k < v->n && *json; k++) {
            cJSON *c;
            snprintf(sub, 1024, "%s%s%lld", path, *path ? "." : "", (long long)k);
            g3d_status rc = walk_value(w, v->items[k], sub, &c);
            if (rc != G3D_OK) { cJSON_Delete(*json); *json = NULL; return rc; }
            cJSON_AddItemToArray(*json, c);
        }
        break;
    case V_DICT:
        *json = cJSON_CreateObject();
        for (int64_t k = 0; k + 1 < v->n && *json; k += 2) {
            const value *key = v->items[k];
            char kbuf[32];
            /* a class as key (a training framework's callbacks) is named by its dotted name */
            const char *ks = key->kind == V_STR || key->kind == V_GLOBAL || key->kind == V_OPAQUE ? key->s : NULL;
            if (key->kind == V_INT) { snprintf(kbuf, sizeof kbuf, "%lld", (long long)key->i); ks = kbuf; }
            cJSON *c;
            g3d_status rc = G3D_OK;
            if (!ks) {
                rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: a dict key in data.pkl is neither a string, an integer nor a class", w->ck->path);
            } else {
                snprintf(sub, 1024, "%s%s%s", path, *path ? "." : "", ks);
                rc = walk_value(w, v->items[k + 1], sub, &c);
            }
            if (rc != G3D_OK) { cJSON_Delete(*json); *json = NULL; return rc; }
            cJSON_AddItemToObject(*json, ks, c);
        }
        break;
    default:
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl holds an object other than tensors and plain containers", w->ck->path);
    }
    if (!*json) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    return G3D_OK;
}

/* Past the bounds it answers "no"; walk_value then reports the problem. */
static int holds_tensor(const value *v, int depth, int64_t *visits)
{
    if (depth >= WALK_MAX_DEPTH || ++*visits > WALK_MAX_VISITS) return 0;
    if (v->kind == V_TENSOR) return 1;
    if (v->kind == V_DICT || v->kind == V_LIST || v->kind == V_TUPLE)
        for (int64_t k = 0; k < v->n; k++)
            if (holds_tensor(v->items[k], depth + 1, visits)) return 1;
    return 0;
}

g3d_status g3d__torch_index(g3d_ckpt *ck)
{
    g3d_zip zip;
    G3D_TRY(g3d_zip_open(&zip, ck->data, ck->size, ck->path));
    int64_t pkl = -1;
    for (int64_t i = 0; i < zip.n_entries; i++) {
        const char *nm = zip.entries[i].name, *slash = strchr(nm, '/');
        if (slash && !strcmp(slash, "/data.pkl")) {
            if (pkl >= 0) { g3d_zip_close(&zip); return G3D_ERR(G3D_ERR_FORMAT, "%s: more than one data.pkl", ck->path); }
            pkl = i;
        }
    }
    if (pkl < 0) { g3d_zip_close(&zip); return G3D_ERR(G3D_ERR_FORMAT, "%s: a zip file, but not a PyTorch checkpoint (no data.pkl)", ck->path); }
    char prefix[256];
    size_t plen = strlen(zip.entries[pkl].name) - strlen("/data.pkl");
    if (plen >= sizeof prefix) { g3d_zip_close(&zip); return G3D_ERR(G3D_ERR_FORMAT, "%s: archive name too long", ck->path); }
    memcpy(prefix, zip.entries[pkl].name, plen);
    prefix[plen] = 0;
    char bo_name[300];
    snprintf(bo_name, sizeof bo_name, "%s/byteorder", prefix);
    int64_t bo = g3d_zip_find(&zip, bo_name);
    if (bo >= 0 && zip.entries[bo].size >= 3 && !memcmp(zip.data + zip.entries[bo].offset, "big", 3) && zip.entries[bo].method == 0) {
        g3d_zip_close(&zip);
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: big-endian checkpoints are not supported", ck->path);
    }
    unsigned char *buf = NULL;
    uint64_t n = 0;
    g3d_status rc = g3d_zip_extract(&zip, pkl, MAX_PICKLE_BYTES, &buf, &n);
    unpickler u;
    memset(&u, 0, sizeof u);
    u.label = ck->path;
    u.scan_left = (int64_t)1 << 24;
    u.p = buf;
    u.end = buf ? buf + n : buf;
    value *root = NULL;
    if (rc == G3D_OK) rc = run_pickle(&u, &root);
    if (rc == G3D_OK) {
        walk w = {ck, &zip, prefix, 0, 0, 0};
        /* {'model': state_dict, ...}: when exactly one top-level entry holds tensors and it is
         * a dict, tensors are named by their state-dict keys without that wrapper key. A
         * PyTorch Lightning checkpoint also keeps tensors in its callbacks' and optimizers'
         * states: there the 'state_dict' entry loses its key and the rest keep their paths. */
        const value *tensors_at = root;
        const char *strip = NULL;
        int64_t visits = 0, lightning = -1;
        if (root->kind == V_DICT) {
            int holders = 0;
            for (int64_t k = 0; k + 1 < root->n; k += 2) {
                const value *key = root->items[k], *val = root->items[k + 1];
                if (!holds_tensor(val, 1, &visits)) continue;
                holders++;
                tensors_at = val;
                strip = key->kind == V_STR ? key->s : NULL;
                if (key->kind == V_STR && !strcmp(key->s, "state_dict") && val->kind == V_DICT) lightning = k;
            }
            if (holders > 1 && lightning >= 0) {
                tensors_at = root->items[lightning + 1];
                strip = root->items[lightning]->s;
            } else if (holders != 1 || tensors_at->kind != V_DICT || !strip) {
                tensors_at = root;
                strip = NULL;
            }
        }
        cJSON *json = NULL;
        if (strip) {
            /* Index the state dict without its key, then describe the rest of the object. */
            cJSON *sd = NULL;
            rc = walk_value(&w, tensors_at, "", &sd);
            if (rc == G3D_OK) {
                json = cJSON_CreateObject();
                for (int64_t k = 0; k + 1 < root->n && rc == G3D_OK && json; k += 2) {
                    const value *key = root->items[k];
                    if (key->kind == V_STR && key->s == strip) { cJSON_AddItemToObject(json, key->s, sd); sd = NULL; continue; }
                    cJSON *c = NULL;
                    rc = key->kind == V_STR ? walk_value(&w, root->items[k + 1], key->s, &c)
                                            : G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: a top-level key is not a string", ck->path);
                    if (rc == G3D_OK) cJSON_AddItemToObject(json, key->s, c);
                }
            }
            cJSON_Delete(sd);
        } else {
            rc = walk_value(&w, root, "", &json);
        }
        if (rc == G3D_OK) ck->meta = json;
        else cJSON_Delete(json);
    }
    unpickler_free(&u);
    free(buf);
    g3d_zip_close(&zip);
    return rc;
}
