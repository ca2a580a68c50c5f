/* The samplers against their reference code (tests/fixtures/make_sdsample_golden.py): ldm's
 * DDIM (epsilon, and v with eta 0.5) and PLMS, k-diffusion's Euler, Euler ancestral and DPM++ 2M on
 * the discrete and Karras sigmas, diffusers' PNDM, each a whole denoising trajectory of the tiny SD 1.x UNet from
 * the recorded initial noise with classifier-free guidance; their schedules; refusals. */
#include "golden.h"

#include "gen3d/sd.h"

static g3d_ckpt *g_act;
static g3d_sd_unet *g_unet;

/* Classifier-free guidance with two passes of the UNet. */
typedef struct guided {
    const float *cond, *uncond;
    float scale;
    int calls;
} guided;

static g3d_status model(void *ctx, const float *x, float t, float *out)
{
    guided *g = ctx;
    float u[4 * 8 * 12];
    G3D_TRY(g3d_sd_unet_forward(g_unet, x, 8, 12, t, g->uncond, 77, u, NULL, NULL));
    G3D_TRY(g3d_sd_unet_forward(g_unet, x, 8, 12, t, g->cond, 77, out, NULL, NULL));
    for (int i = 0; i < 4 * 8 * 12; i++) out[i] = u[i] + g->scale * (out[i] - u[i]);
    g->calls++;
    return G3D_OK;
}

/* The recorded noise, draw after draw. */
typedef struct recorded {
    const float *z;
    size_t n, used;
} recorded;

static void noise(void *ctx, float *z, size_t n)
{
    recorded *r = ctx;
    CHECK_MSG(r->used + n <= r->n, "more noise drawn than recorded");
    if (r->used + n > r->n) return;
    memcpy(z, r->z + r->used, sizeof(float) * n);
    r->used += n;
}

typedef struct steps {
    const char *run;
} steps;

static int on_step(void *ctx, int i, int total, float *x, size_t n, float a, float b)
{
    steps *s = ctx;
    char name[64];
    (void)total, (void)a, (void)b;
    snprintf(name, sizeof name, "%s.x%d", s->run, i + 1);
    if (g3d_ckpt_find(g_act, name)) golden_compare(g_act, name, x, n);
    return 0;
}

static void check_run(const char *run, g3d_sd_sampler_kind kind, int nsteps, int karras, g3d_sd_pred pred, float eta, float scale)
{
    char name[64];
    size_t n = 4 * 8 * 12, nz = 0;
    float *x = golden_floats(g_act, "noise", NULL), *cond = golden_floats(g_act, "cond", NULL), *uncond = golden_floats(g_act, "uncond", NULL);
    snprintf(name, sizeof name, "%s.noise", run);
    float *z = g3d_ckpt_find(g_act, name) ? golden_floats(g_act, name, &nz) : NULL;
    printf("  %s\n", run);
    /* the schedule */
    if (kind == G3D_SD_DDIM || kind == G3D_SD_PNDM || kind == G3D_SD_PLMS) {
        int ts[G3D_SD_TRAIN_STEPS];
        int k = kind != G3D_SD_PNDM ? g3d_sd_ddim_timesteps(nsteps, ts) : g3d_sd_pndm_timesteps(nsteps, ts);
        snprintf(name, sizeof name, "%s.timesteps", run);
        const g3d_tensor_info *t = g3d_ckpt_find(g_act, name);
        CHECK(t && t->numel == k && !memcmp(t->data, ts, sizeof(int) * (size_t)k));
    } else {
        float sig[64];
        g3d_sd_sigmas(nsteps, karras, sig);
        snprintf(name, sizeof name, "%s.sigmas", run);
        golden_compare(g_act, name, sig, (size_t)nsteps + 1);
    }
    guided g = {cond, uncond, scale, 0};
    recorded r = {z, nz, 0};
    steps st = {run};
    g3d_sd_sampler s = {kind, nsteps, eta, karras, pred};
    if (x && cond && uncond) {
        CHECK_OK(g3d_sd_sample(&s, x, n, model, &g, z ? noise : NULL, &r, on_step, &st));
        snprintf(name, sizeof name, "%s.x", run);
        golden_compare(g_act, name, x, n);
        CHECK(r.used == nz);
    }
    free(x);
    free(cond);
    free(uncond);
    free(z);
}

TEST(ddim)
{
    check_run("ddim_eps", G3D_SD_DDIM, 10, 0, G3D_SD_PRED_EPS, 0.0f, 7.5f);
    check_run("ddim_v_eta", G3D_SD_DDIM, 7, 0, G3D_SD_PRED_V, 0.5f, 3.0f);
}

TEST(k_diffusion)
{
    check_run("euler", G3D_SD_EULER, 10, 0, G3D_SD_PRED_EPS, 0, 7.5f);
    check_run("euler_a_karras", G3D_SD_EULER_A, 8, 1, G3D_SD_PRED_EPS, 0, 5.0f);
    check_run("dpmpp_2m", G3D_SD_DPMPP_2M, 10, 0, G3D_SD_PRED_EPS, 0, 7.5f);
    check_run("dpmpp_2m_karras_v", G3D_SD_DPMPP_2M, 9, 1, G3D_SD_PRED_V, 0, 4.0f);
}

TEST(pndm)
{
    check_run("pndm_eps", G3D_SD_PNDM, 10, 0, G3D_SD_PRED_EPS, 0, 7.5f);
    check_run("pndm_v", G3D_SD_PNDM, 6, 0, G3D_SD_PRED_V, 0, 3.0f);
}

TEST(plms)
{
    check_run("plms_eps", G3D_SD_PLMS, 10, 0, G3D_SD_PRED_EPS, 0, 7.5f);
    check_run("plms_eps7", G3D_SD_PLMS, 7, 0, G3D_SD_PRED_EPS, 0, 3.0f);
}

TEST(names_and_refusals)
{
    CHECK(g3d_sd_sampler_parse("euler_a") == G3D_SD_EULER_A && g3d_sd_sampler_parse("dpm++2m") == G3D_SD_DPMPP_2M &&
          g3d_sd_sampler_parse("plms") == G3D_SD_PLMS && g3d_sd_sampler_parse("lms") == -1);
    float x[4 * 8 * 12] = {0};
    guided g = {x, x, 1, 0};
    g3d_sd_sampler s = {G3D_SD_EULER_A, 4, 0, 0, G3D_SD_PRED_EPS};
    CHECK_FAILS(g3d_sd_sample(&s, x, 4 * 8 * 12, model, &g, NULL, NULL, NULL, NULL));   /* ancestral without noise */
    /* ldm's PLMS: noise prediction and eta 0 only */
    s.kind = G3D_SD_PLMS;
    s.pred = G3D_SD_PRED_V;
    CHECK_FAILS(g3d_sd_sample(&s, x, 4 * 8 * 12, model, &g, NULL, NULL, NULL, NULL));
    s.pred = G3D_SD_PRED_EPS;
    s.eta = 0.5f;
    CHECK_FAILS(g3d_sd_sample(&s, x, 4 * 8 * 12, model, &g, NULL, NULL, NULL, NULL));
    s.eta = 0;
    s.kind = G3D_SD_EULER;
    s.steps = 0;
    CHECK_FAILS(g3d_sd_sample(&s, x, 4 * 8 * 12, model, &g, NULL, NULL, NULL, NULL));
    CHECK(g.calls == 0);
}

int main(void)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdsample_golden.safetensors"), &g_act));
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_sd1_tiny.ckpt"), &ck));
    if (ck) CHECK_OK(g3d_sd_unet_load(ck, NULL, &g_unet));
    if (g_act && g_unet) {
        RUN(ddim);
        RUN(k_diffusion);
        RUN(pndm);
        RUN(plms);
        RUN(names_and_refusals);
    }
    g3d_sd_unet_free(g_unet);
    g3d_ckpt_free(ck);
    g3d_ckpt_free(g_act);
    return test_summary();
}
