/* Linear layers: y = x W^T + b with W packed once into the kernel's 64-column panels. */
#include "nn/nn_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static uint16_t to_bf16(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    if ((u & 0x7fffffff) > 0x7f800000) return (uint16_t)((u >> 16) | 0x40); /* quiet NaN */
    u += 0x7fff + ((u >> 16) & 1);                                         /* round to nearest even */
    return (uint16_t)(u >> 16);
}

static uint16_t to_f16(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    uint32_t sign = (u >> 16) & 0x8000, a = u & 0x7fffffff;
    if (a > 0x7f800000) return (uint16_t)(sign | 0x7e00);
    if (a >= 0x477ff000) return (uint16_t)(sign | 0x7c00); /* rounds past 65504: inf */
    if (a < 0x38800000) {                                  /* subnormal or zero in half */
        float v;
        memcpy(&v, &a, 4);
        /* units of 2^-24, rounded to nearest even by the FPU */
        return (uint16_t)(sign | (uint32_t)nearbyintf(v * 16777216.0f));
    }
    uint32_t r = a + 0x0fff + ((a >> 13) & 1) - 0x38000000;
    return (uint16_t)(sign | (r >> 13));
}

g3d_status g3d_nn_lin_init(g3d_nn_lin *L, const void *w, g3d_dtype wtype, const float *b, int out, int in,
                           g3d_dtype store)
{
    memset(L, 0, sizeof *L);
    if (out <= 0 || in <= 0) return G3D_ERR(G3D_ERR_ARG, "linear: bad size %d x %d", out, in);
    if (wtype != G3D_DT_F32 && wtype != G3D_DT_F16 && wtype != G3D_DT_BF16)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "linear: weights of type %s", g3d_dtype_name(wtype));
    if (store != G3D_DT_F32 && store != G3D_DT_F16 && store != G3D_DT_BF16)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "linear: cannot store weights as %s", g3d_dtype_name(store));
    const int npan = (out + NN_NR - 1) / NN_NR;
    const size_t esz = store == G3D_DT_F32 ? 4 : 2, n = (size_t)npan * in * NN_NR;
    L->panels = aligned_alloc(64, (n * esz + 63) / 64 * 64);
    L->bias = b ? malloc(sizeof(float) * (size_t)out) : NULL;
    int ok = L->panels && (!b || L->bias);
#pragma omp parallel if (ok)
    {
        float *row = malloc(sizeof(float) * (size_t)in);
        if (!row) {
#pragma omp atomic write
            ok = 0;
        }
#pragma omp for schedule(static)
        for (int j = 0; j < npan * NN_NR; j++) {
            if (!row) continue;
            /* one output unit: row j of W becomes column j%64 of panel j/64 */
            if (j < out)
                g3d_dtype_to_f32(wtype, (const char *)w + (size_t)j * in * g3d_dtype_size(wtype), row, in);
            else
                memset(row, 0, sizeof(float) * (size_t)in);
            size_t base = (size_t)(j / NN_NR) * in * NN_NR + j % NN_NR;
            for (int k = 0; k < in; k++) {
                size_t at = base + (size_t)k * NN_NR;
                if (store == G3D_DT_F32)
                    ((float *)L->panels)[at] = row[k];
                else
                    ((uint16_t *)L->panels)[at] = store == G3D_DT_BF16 ? to_bf16(row[k]) : to_f16(row[k]);
            }
        }
        free(row);
    }
    if (!ok) {
        g3d_nn_lin_free(L);
        return G3D_ERR(G3D_ERR_NOMEM, "linear: cannot allocate %d x %d packed weights", out, in);
    }
    if (b) memcpy(L->bias, b, sizeof(float) * (size_t)out);
    L->in = in, L->out = out, L->store = store;
    return G3D_OK;
}

void g3d_nn_lin_free(g3d_nn_lin *L)
{
    free(L->panels);
    free(L->bias);
    memset(L, 0, sizeof *L);
}

g3d_status g3d_nn_lin_forward(const g3d_nn_lin *L, const float *x, int n, int ldx, float *y, int ldy,
                              const g3d_nn_epi *epi)
{
    if (n < 0) return G3D_ERR(G3D_ERR_ARG, "linear: negative row count %d", n);
    nn_gemm g = {.M = n, .N = L->out, .K = L->in, .a = x, .lda = ldx ? ldx : L->in, .ka = 1,
                 .bkind = NN_B_PANELS, .b = L->panels, .bt = L->store, .y = y, .ldy = ldy ? ldy : L->out,
                 .alpha = 1.0f, .bias = L->bias, .epi = epi};
    return nn_gemm_run(&g);
}

void g3d_nn_linear(const float *x, int n, int in, const float *w, const float *b, int out, float *y)
{
    /* Few rows: every column block of W is packed once anyway, inside its tile. More rows:
     * pack W once up front rather than once per row tile. */
    g3d_status rc;
    if (n <= 96) {
        nn_gemm g = {.M = n, .N = out, .K = in, .a = x, .lda = in, .ka = 1, .bkind = NN_B_COLS, .b = w,
                     .ldb = in, .y = y, .ldy = out, .alpha = 1.0f, .bias = b};
        rc = nn_gemm_run(&g);
    } else {
        g3d_nn_lin L;
        rc = g3d_nn_lin_init(&L, w, G3D_DT_F32, NULL, out, in, G3D_DT_F32);
        if (rc == G3D_OK) {
            L.bias = (float *)b; /* borrowed: not freed below */
            rc = g3d_nn_lin_forward(&L, x, n, in, y, out, NULL);
            L.bias = NULL;
            g3d_nn_lin_free(&L);
        }
    }
    if (rc != G3D_OK) {
        g3d_error_clear();
        nn_ref_linear(x, n, in, w, b, out, NULL, y);
    }
}

void nn_ref_linear(const float *x, int n, int in, const float *w, const float *b, int out, const g3d_nn_epi *epi,
                   float *y)
{
    for (int i = 0; i < n; i++)
        for (int o = 0; o < out; o++) {
            double s = b ? b[o] : 0.0;
            for (int k = 0; k < in; k++) s += (double)x[(size_t)i * in + k] * w[(size_t)o * in + k];
            float v = (float)s;
            if (epi) {
                v = nn_ref_act1(epi->act, v);
                if (epi->scale) v *= epi->scale[o];
                if (epi->res) v += epi->res[(size_t)i * out + o];
            }
            y[(size_t)i * out + o] = v;
        }
}
