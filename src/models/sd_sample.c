/* Stable Diffusion's samplers: ldm's DDIM and k-diffusion's Euler, Euler ancestral and
 * DPM++ 2M on the discrete or Karras sigmas, with the arithmetic in the order the reference
 * code uses (float32 schedule tables, as they hold them). */
#include "gen3d/sd.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const NAMES[G3D_SD_SAMPLER_COUNT] = {"ddim", "euler", "euler_a", "dpmpp_2m", "pndm", "plms"};

int g3d_sd_sampler_parse(const char *name)
{
    for (int k = 0; k < G3D_SD_SAMPLER_COUNT; k++)
        if (!strcmp(name, NAMES[k])) return k;
    if (!strcmp(name, "dpm++2m") || !strcmp(name, "dpm++_2m")) return G3D_SD_DPMPP_2M;
    return -1;
}

const char *g3d_sd_sampler_name(g3d_sd_sampler_kind k) { return k >= 0 && k < G3D_SD_SAMPLER_COUNT ? NAMES[k] : "?"; }

void g3d_sd_alphas_cumprod(float *ac)
{
    /* ldm's make_beta_schedule("linear"): linspace of the square roots in float64, squared */
    const int n = G3D_SD_TRAIN_STEPS;
    double a = sqrt(0.00085), b = sqrt(0.012), step = (b - a) / (n - 1), prod = 1;
    for (int i = 0; i < n; i++) {
        /* torch.linspace fills the second half from the end */
        double r = i < n / 2 ? a + step * i : b - step * (n - 1 - i);
        prod *= 1.0 - r * r;
        ac[i] = (float)prod;
    }
}

int g3d_sd_ddim_timesteps(int steps, int *t)
{
    int c = G3D_SD_TRAIN_STEPS / (steps < 1 ? 1 : steps > G3D_SD_TRAIN_STEPS ? G3D_SD_TRAIN_STEPS : steps), k = 0;
    for (int v = 0; v < G3D_SD_TRAIN_STEPS; v += c) k++;
    for (int i = 0; i < k; i++) t[i] = (k - 1 - i) * c + 1;
    /* the last level has no successor: range(0, 1000, 1) + 1 would index 1000 */
    if (t[0] >= G3D_SD_TRAIN_STEPS) t[0] = G3D_SD_TRAIN_STEPS - 1;
    return k;
}

/* The 1000 training sigmas and their logarithms, in float32. */
static void train_sigmas(float *sig, float *logsig)
{
    float ac[G3D_SD_TRAIN_STEPS];
    g3d_sd_alphas_cumprod(ac);
    for (int i = 0; i < G3D_SD_TRAIN_STEPS; i++) {
        sig[i] = sqrtf((1.0f - ac[i]) / ac[i]);
        logsig[i] = logf(sig[i]);
    }
}

void g3d_sd_sigmas(int steps, int karras, float *out)
{
    float sig[G3D_SD_TRAIN_STEPS], ls[G3D_SD_TRAIN_STEPS];
    train_sigmas(sig, ls);
    int n = steps;
    for (int i = 0; i < n; i++) {
        float ramp = n > 1 ? (float)i / (float)(n - 1) : 0.0f;
        if (karras) {
            double rho = 7.0, lo = pow(sig[0], 1 / rho), hi = pow(sig[G3D_SD_TRAIN_STEPS - 1], 1 / rho);
            out[i] = powf((float)(hi + ramp * (lo - hi)), (float)rho);
        } else {
            /* t from 999 down to 0, log-sigma interpolated between the neighbouring levels */
            float t = n > 1 ? (float)(G3D_SD_TRAIN_STEPS - 1) * (1.0f - ramp) : (float)(G3D_SD_TRAIN_STEPS - 1);
            int lo = (int)floorf(t), hi = (int)ceilf(t);
            float w = t - (float)lo;
            out[i] = expf((1.0f - w) * ls[lo] + w * ls[hi]);
        }
    }
    out[n] = 0.0f;
}

/* k-diffusion's sigma_to_t: the fractional training step of a noise level. */
static float sigma_to_t(const float *ls, float sigma)
{
    float l = logf(sigma);
    int lo = 0;
    for (int i = 0; i < G3D_SD_TRAIN_STEPS; i++)
        if (l - ls[i] >= 0) lo = i;
    if (lo > G3D_SD_TRAIN_STEPS - 2) lo = G3D_SD_TRAIN_STEPS - 2;
    float w = (ls[lo] - l) / (ls[lo] - ls[lo + 1]);
    w = w < 0 ? 0 : w > 1 ? 1 : w;
    return (1.0f - w) * (float)lo + w * (float)(lo + 1);
}

typedef struct run {
    const g3d_sd_sampler *s;
    size_t n;
    g3d_sd_model_fn model;
    void *mctx;
    g3d_sd_noise_fn noise;
    void *nctx;
    g3d_sd_step_fn step;
    void *sctx;
    float *out, *tmp, *z;
} run;

static g3d_status after_step(const run *r, int i, int total, float *x, float a, float b)
{
    if (r->step && r->step(r->sctx, i, total, x, r->n, a, b)) return G3D_CANCELLED;
    return G3D_OK;
}

/* after_step for the samplers on training timesteps: the next timestep's sqrt(alphas_cumprod)
 * and sqrt(1 - alphas_cumprod), 1 and 0 after the last step. */
static g3d_status after_timestep(const run *r, const float *ac, const int *ts, int i, int total, float *x)
{
    float a = i + 1 < total ? sqrtf(ac[ts[i + 1]]) : 1.0f, b = i + 1 < total ? sqrtf(1.0f - ac[ts[i + 1]]) : 0.0f;
    return after_step(r, i, total, x, a, b);
}

static g3d_status need_noise(const run *r)
{
    if (!r->noise) return G3D_ERR(G3D_ERR_ARG, "the %s sampler needs a noise source", g3d_sd_sampler_name(r->s->kind));
    return G3D_OK;
}

static g3d_status ddim(const run *r, float *x)
{
    float ac[G3D_SD_TRAIN_STEPS];
    int ts[G3D_SD_TRAIN_STEPS];
    g3d_sd_alphas_cumprod(ac);
    int k = g3d_sd_ddim_timesteps(r->s->steps, ts);
    int v = r->s->pred == G3D_SD_PRED_V;
    double eta = r->s->eta;
    if (eta != 0) G3D_TRY(need_noise(r));
    for (int i = 0; i < k; i++) {
        int t = ts[i];
        double at = ac[t], ap = i + 1 < k ? ac[ts[i + 1]] : ac[0];
        double sigma = eta * sqrt((1 - ap) / (1 - at) * (1 - at / ap));
        float sa = sqrtf(ac[t]), sb = sqrtf(1.0f - ac[t]);
        G3D_TRY(r->model(r->mctx, x, (float)t, r->out));
        if (eta != 0) r->noise(r->nctx, r->z, r->n);
        double dir = sqrt(1 - ap - sigma * sigma), sap = sqrt(ap);
        for (size_t j = 0; j < r->n; j++) {
            double o = r->out[j], e, x0;
            if (v) {
                e = (double)sa * o + (double)sb * x[j];
                x0 = (double)sa * x[j] - (double)sb * o;
            } else {
                e = o;
                x0 = (x[j] - sqrt(1 - at) * e) / sqrt(at);
            }
            x[j] = (float)(sap * x0 + dir * e + (eta != 0 ? sigma * r->z[j] : 0));
        }
        G3D_TRY(after_timestep(r, ac, ts, i, k, x));
    }
    return G3D_OK;
}

/* ldm's PLMSSampler: DDIM's timesteps and deterministic update, fed with a pseudo linear
 * multistep estimate of the noise: the first step a pseudo improved Euler step (the model
 * again at the next timestep on DDIM's step, the two estimates averaged: N + 1 model calls),
 * then Adams-Bashforth of order 2, 3 and 4 over the model's earlier outputs. */
static g3d_status plms(const run *r, float *x)
{
    if (r->s->pred != G3D_SD_PRED_EPS) return G3D_ERR(G3D_ERR_ARG, "ldm's PLMS sampler takes noise-predicting (epsilon) models only");
    if (r->s->eta != 0) return G3D_ERR(G3D_ERR_ARG, "ldm's PLMS sampler has no eta (it must be 0)");
    float ac[G3D_SD_TRAIN_STEPS];
    int ts[G3D_SD_TRAIN_STEPS];
    g3d_sd_alphas_cumprod(ac);
    int k = g3d_sd_ddim_timesteps(r->s->steps, ts), nold = 0;
    /* the last three outputs (a ring), the current one, the pseudo Euler step's latent */
    float *old = malloc(sizeof(float) * 3 * r->n), *e = malloc(sizeof(float) * r->n), *xp = malloc(sizeof(float) * r->n);
    g3d_status rc = old && e && xp ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the sampler");
    for (int i = 0; rc == G3D_OK && i < k; i++) {
        int t = ts[i], tn = ts[i + 1 < k ? i + 1 : k - 1];
        double at = ac[t], ap = i + 1 < k ? ac[ts[i + 1]] : ac[0];
        double sa = sqrt(at), sb = sqrt(1 - at), sap = sqrt(ap), dir = sqrt(1 - ap);
        if ((rc = r->model(r->mctx, x, (float)t, e)) != G3D_OK) break;
        const float *o1 = old + (size_t)((nold + 2) % 3) * r->n, *o2 = old + (size_t)((nold + 1) % 3) * r->n, *o3 = old + (size_t)(nold % 3) * r->n;
        if (nold == 0) {
            for (size_t j = 0; j < r->n; j++) xp[j] = (float)(sap * ((x[j] - sb * e[j]) / sa) + dir * e[j]);
            if ((rc = r->model(r->mctx, xp, (float)tn, r->out)) != G3D_OK) break;
        }
        for (size_t j = 0; j < r->n; j++) {
            double m;
            if (nold == 0) m = ((double)e[j] + r->out[j]) / 2.0;
            else if (nold == 1) m = (3.0 * e[j] - o1[j]) / 2.0;
            else if (nold == 2) m = (23.0 * e[j] - 16.0 * o1[j] + 5.0 * o2[j]) / 12.0;
            else m = (55.0 * e[j] - 59.0 * o1[j] + 37.0 * o2[j] - 9.0 * o3[j]) / 24.0;
            x[j] = (float)(sap * ((x[j] - sb * m) / sa) + dir * m);
        }
        memcpy(old + (size_t)(nold % 3) * r->n, e, sizeof(float) * r->n);
        nold++;
        rc = after_timestep(r, ac, ts, i, k, x);
    }
    free(old);
    free(e);
    free(xp);
    return rc;
}

/* k-diffusion's CompVis denoisers: the denoised latent d at noise level sigma. */
static g3d_status denoise(const run *r, const float *ls, const float *x, float sigma, float *d)
{
    double s2 = (double)sigma * sigma, cin = 1 / sqrt(s2 + 1);
    for (size_t j = 0; j < r->n; j++) r->tmp[j] = (float)(x[j] * cin);
    G3D_TRY(r->model(r->mctx, r->tmp, sigma_to_t(ls, sigma), r->out));
    if (r->s->pred == G3D_SD_PRED_V) {
        double cskip = 1 / (s2 + 1), cout = -sigma / sqrt(s2 + 1);
        for (size_t j = 0; j < r->n; j++) d[j] = (float)(r->out[j] * cout + x[j] * cskip);
    } else {
        for (size_t j = 0; j < r->n; j++) d[j] = (float)(x[j] + r->out[j] * -(double)sigma);
    }
    return G3D_OK;
}

static g3d_status kdiff(const run *r, float *x)
{
    const g3d_sd_sampler *s = r->s;
    int N = s->steps;
    float tsig[G3D_SD_TRAIN_STEPS], ls[G3D_SD_TRAIN_STEPS];
    float *sig = malloc(sizeof(float) * (size_t)(N + 1)), *d = malloc(sizeof(float) * r->n);
    float *old = s->kind == G3D_SD_DPMPP_2M ? malloc(sizeof(float) * r->n) : NULL;
    g3d_status rc = sig && d && (old || s->kind != G3D_SD_DPMPP_2M) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the sampler");
    if (rc == G3D_OK && s->kind == G3D_SD_EULER_A) rc = need_noise(r);
    if (rc == G3D_OK) {
        train_sigmas(tsig, ls);
        g3d_sd_sigmas(N, s->karras, sig);
        for (size_t j = 0; j < r->n; j++) x[j] *= sig[0];
    }
    for (int i = 0; rc == G3D_OK && i < N; i++) {
        double sg = sig[i], sn = sig[i + 1];
        rc = denoise(r, ls, x, sig[i], d);
        if (rc != G3D_OK) break;
        if (s->kind == G3D_SD_EULER) {
            for (size_t j = 0; j < r->n; j++) x[j] = (float)(x[j] + (x[j] - d[j]) / sg * (sn - sg));
        } else if (s->kind == G3D_SD_EULER_A) {
            double up = sqrt(sn * sn * (sg * sg - sn * sn) / (sg * sg));
            if (up > sn) up = sn;
            double down = sqrt(sn * sn - up * up);
            for (size_t j = 0; j < r->n; j++) x[j] = (float)(x[j] + (x[j] - d[j]) / sg * (down - sg));
            if (sn > 0) {
                r->noise(r->nctx, r->z, r->n);
                for (size_t j = 0; j < r->n; j++) x[j] = (float)(x[j] + r->z[j] * up);
            }
        } else {
            /* DPM-Solver++(2M) in t = -log sigma; first order on the first and last steps */
            double h = -log(sn) + log(sg), ratio = sn / sg, em = expm1(-h);
            if (i == 0 || sn == 0) {
                for (size_t j = 0; j < r->n; j++) x[j] = (float)(ratio * x[j] - em * d[j]);
            } else {
                double hl = -log(sg) + log(sig[i - 1]), rr = hl / h;
                double c1 = 1 + 1 / (2 * rr), c2 = 1 / (2 * rr);
                for (size_t j = 0; j < r->n; j++) x[j] = (float)(ratio * x[j] - em * (c1 * d[j] - c2 * old[j]));
            }
            memcpy(old, d, sizeof(float) * r->n);
        }
        rc = after_step(r, i, N, x, 1.0f, (float)sn);
    }
    free(sig);
    free(d);
    free(old);
    return rc;
}

int g3d_sd_pndm_timesteps(int steps, int *t)
{
    int r = G3D_SD_TRAIN_STEPS / steps;
    /* "leading" spacing i r + 1, the second-to-last repeated (there is none for one step), in reverse */
    t[0] = (steps - 1) * r + 1;
    for (int i = 1; i <= steps; i++) t[i] = (steps - (i > 1 ? i : 2)) * r + 1;
    return steps == 1 ? 1 : steps + 1;
}

/* diffusers' schedule: betas = linspace(sqrt 0.00085, sqrt 0.012)^2 and their cumulative
 * product, all in float32 as torch computes them there. */
static void pndm_alphas(float *ac)
{
    const int n = G3D_SD_TRAIN_STEPS;
    float a = sqrtf(0.00085f), b = sqrtf(0.012f), step = (b - a) / (float)(n - 1), prod = 1.0f;
    for (int i = 0; i < n; i++) {
        float r = i < n / 2 ? a + step * (float)i : b - step * (float)(n - 1 - i);
        prod *= 1.0f - r * r;
        ac[i] = prod;
    }
}

static g3d_status pndm(const run *r, float *x)
{
    int N = r->s->steps, ratio = G3D_SD_TRAIN_STEPS / N, v = r->s->pred == G3D_SD_PRED_V, calls = 0;
    float ac[G3D_SD_TRAIN_STEPS];
    int *ts = malloc(sizeof(int) * (size_t)(N + 1));
    /* the last four model outputs (a ring) and the sample before the first step */
    float *ets = malloc(sizeof(float) * 4 * r->n), *first = malloc(sizeof(float) * r->n);
    g3d_status rc = ts && ets && first ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the sampler");
    if (rc == G3D_OK) {
        pndm_alphas(ac);
        calls = g3d_sd_pndm_timesteps(N, ts);
    }
    int nets = 0;
    for (int k = 0; rc == G3D_OK && k < calls; k++) {
        int t = ts[k], prev = t - ratio;
        rc = r->model(r->mctx, x, (float)t, r->out);
        if (rc != G3D_OK) break;
        const float *e[4];
        float *sample = x;
        if (k != 1) {
            memcpy(ets + (size_t)(nets % 4) * r->n, r->out, sizeof(float) * r->n);
            nets++;
        } else {
            /* the warm-up's second call: a Heun-like average, from the first sample again */
            prev = t;
            t += ratio;
            sample = first;
        }
        for (int i = 0; i < 4 && i < nets; i++) e[i] = ets + (size_t)((nets - 1 - i) % 4) * r->n;
        if (k == 0) memcpy(first, x, sizeof(float) * r->n);
        double at = ac[t], ap = prev >= 0 ? ac[prev] : ac[0], bt = 1 - at, bp = 1 - ap;
        double sc = sqrt(ap / at), den = at * sqrt(bp) + sqrt(at * bt * ap);
        for (size_t j = 0; j < r->n; j++) {
            double m;
            if (k == 1) m = (r->out[j] + e[0][j]) / 2.0;
            else if (nets == 1) m = e[0][j];
            else if (nets == 2) m = (3.0 * e[0][j] - e[1][j]) / 2.0;
            else if (nets == 3) m = (23.0 * e[0][j] - 16.0 * e[1][j] + 5.0 * e[2][j]) / 12.0;
            else m = (55.0 * e[0][j] - 59.0 * e[1][j] + 37.0 * e[2][j] - 9.0 * e[3][j]) / 24.0;
            double s = sample[j];
            if (v) m = sqrt(at) * m + sqrt(bt) * s;
            x[j] = (float)(sc * s - (ap - at) * m / den);
        }
        rc = after_timestep(r, ac, ts, k, calls, x);
    }
    free(ts);
    free(ets);
    free(first);
    return rc;
}

g3d_status g3d_sd_sample(const g3d_sd_sampler *s, float *x, size_t n, g3d_sd_model_fn model, void *model_ctx,
                         g3d_sd_noise_fn noise, void *noise_ctx, g3d_sd_step_fn step, void *step_ctx)
{
    if (s->kind < 0 || s->kind >= G3D_SD_SAMPLER_COUNT) return G3D_ERR(G3D_ERR_ARG, "unknown sampler %d", (int)s->kind);
    if (s->steps < 1 || s->steps > G3D_SD_TRAIN_STEPS)
        return G3D_ERR(G3D_ERR_ARG, "%d steps: 1 to %d expected", s->steps, G3D_SD_TRAIN_STEPS);
    if (!(s->eta >= 0 && s->eta <= 1)) return G3D_ERR(G3D_ERR_ARG, "eta %g: 0 to 1 expected", s->eta);
    run r = {s, n, model, model_ctx, noise, noise_ctx, step, step_ctx, malloc(sizeof(float) * n), malloc(sizeof(float) * n),
             malloc(sizeof(float) * n)};
    g3d_status rc = r.out && r.tmp && r.z ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the sampler");
    if (rc == G3D_OK)
        rc = s->kind == G3D_SD_DDIM ? ddim(&r, x) : s->kind == G3D_SD_PNDM ? pndm(&r, x) : s->kind == G3D_SD_PLMS ? plms(&r, x) : kdiff(&r, x);
    free(r.out);
    free(r.tmp);
    free(r.z);
    return rc;
}
