/* The automatic prompts: scene categories for CLIP, k-means colours in CIELAB named from a
 * table of our own, and the paper's background template. */
#include "gen3d/describe.h"

#include <cjson/cJSON.h>

#include <ctype.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* Scene types a photograph or a rendered view is likely to show, indoors and outdoors. */
static const char *const CATEGORIES[] = {
    /* indoor */
    "living room", "bedroom", "kitchen", "dining room", "bathroom", "home office", "office", "conference room",
    "classroom", "library", "restaurant", "cafe", "bar", "hotel room", "hotel lobby", "hallway", "staircase", "attic",
    "basement", "garage", "warehouse", "factory", "workshop", "laboratory", "hospital room", "gym", "shopping mall",
    "shop", "supermarket", "museum", "art gallery", "church", "theater", "airport terminal", "train station",
    "subway station", "nursery", "laundry room", "indoor swimming pool",
    /* outdoor */
    "city street", "alley", "town square", "parking lot", "park", "garden", "backyard", "playground", "forest", "jungle",
    "mountain", "valley", "desert", "beach", "coast", "ocean", "lake", "river", "waterfall", "field", "farm", "meadow",
    "snowy landscape", "canyon", "cave", "village", "bridge", "harbor", "highway", "country road", "courtyard",
    "stadium", "ruins", "castle", "campsite", "swamp", "night sky",
};

const char *const *g3d_scene_categories(int *n)
{
    *n = (int)(sizeof CATEGORIES / sizeof CATEGORIES[0]);
    return CATEGORIES;
}

void g3d_scene_categories_free(char **labels, int n)
{
    for (int i = 0; labels && i < n; i++) free(labels[i]);
    free(labels);
}

g3d_status g3d_scene_categories_load(const char *path, char ***labels, int *n)
{
    unsigned char *data = NULL;
    size_t len;
    *labels = NULL;
    *n = 0;
    G3D_TRY(g3d_read_file(path, 1 << 20, &data, &len));
    char **out = NULL;
    int count = 0, cap = 0;
    g3d_status rc = G3D_OK;
    for (size_t i = 0; i < len && rc == G3D_OK;) {
        size_t e = i;
        while (e < len && data[e] != '\n') e++;
        size_t a = i, b = e;
        while (a < b && isspace(data[a])) a++;
        while (b > a && isspace(data[b - 1])) b--;
        i = e + 1;
        if (a == b || data[a] == '#') continue;
        if (memchr(data + a, 0, b - a)) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: a NUL byte in a category line (a text file is expected)", path);
            break;
        }
        if (count == cap) {
            cap = cap ? 2 * cap : 32;
            char **grown = realloc(out, sizeof *out * (size_t)cap);
            if (!grown) { rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory"); break; }
            out = grown;
        }
        if (!(out[count] = malloc(b - a + 1))) { rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory"); break; }
        memcpy(out[count], data + a, b - a);
        out[count++][b - a] = 0;
    }
    free(data);
    if (rc == G3D_OK && count == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no categories (one per line expected)", path);
    if (rc != G3D_OK) {
        g3d_scene_categories_free(out, count);
        return rc;
    }
    *labels = out;
    *n = count;
    return G3D_OK;
}

/* ---- colour ------------------------------------------------------------------------------ */
static const double WHITE[3] = {0.95047, 1.0, 1.08883}; /* D65 */

static double lab_f(double t)
{
    const double d = 6.0 / 29.0;
    return t > d * d * d ? cbrt(t) : t / (3 * d * d) + 4.0 / 29.0;
}

static double lab_finv(double t)
{
    const double d = 6.0 / 29.0;
    return t > d ? t * t * t : 3 * d * d * (t - 4.0 / 29.0);
}

void g3d_srgb_to_lab(const float rgb[3], float lab[3])
{
    double l[3];
    for (int i = 0; i < 3; i++) {
        double c = rgb[i];
        l[i] = c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
    }
    double X = (0.4124564 * l[0] + 0.3575761 * l[1] + 0.1804375 * l[2]) / WHITE[0];
    double Y = (0.2126729 * l[0] + 0.7151522 * l[1] + 0.0721750 * l[2]) / WHITE[1];
    double Z = (0.0193339 * l[0] + 0.1191920 * l[1] + 0.9503041 * l[2]) / WHITE[2];
    lab[0] = (float)(116 * lab_f(Y) - 16);
    lab[1] = (float)(500 * (lab_f(X) - lab_f(Y)));
    lab[2] = (float)(200 * (lab_f(Y) - lab_f(Z)));
}

void g3d_lab_to_srgb(const float lab[3], float rgb[3])
{
    double fy = (lab[0] + 16) / 116.0, fx = fy + lab[1] / 500.0, fz = fy - lab[2] / 200.0;
    double X = WHITE[0] * lab_finv(fx), Y = WHITE[1] * lab_finv(fy), Z = WHITE[2] * lab_finv(fz);
    double l[3] = {3.2404542 * X - 1.5371385 * Y - 0.4985314 * Z, -0.9692660 * X + 1.8760108 * Y + 0.0415560 * Z,
                   0.0556434 * X - 0.2040259 * Y + 1.0572252 * Z};
    for (int i = 0; i < 3; i++) {
        double c = l[i] <= 0.0031308 ? 12.92 * l[i] : 1.055 * pow(l[i], 1 / 2.4) - 0.055;
        rgb[i] = (float)(c < 0 ? 0 : c > 1 ? 1 : c);
    }
}

/* Everyday colour names with a representative sRGB value each (8-bit). */
static const struct { const char *name; unsigned char rgb[3]; } NAMES[] = {
    {"black", {0, 0, 0}},           {"charcoal", {54, 54, 54}},        {"dark grey", {96, 96, 96}},
    {"grey", {128, 128, 128}},      {"light grey", {192, 192, 192}},   {"white", {255, 255, 255}},
    {"cream", {245, 240, 225}},     {"beige", {220, 205, 170}},        {"tan", {205, 170, 125}},
    {"khaki", {190, 180, 120}},     {"brown", {120, 75, 40}},          {"dark brown", {70, 45, 25}},
    {"maroon", {110, 20, 30}},      {"red", {200, 30, 30}},            {"terracotta", {200, 100, 70}},
    {"orange", {240, 140, 30}},     {"peach", {250, 200, 160}},        {"gold", {215, 175, 40}},
    {"yellow", {245, 225, 50}},     {"olive", {110, 110, 40}},         {"lime green", {150, 210, 60}},
    {"green", {50, 150, 50}},       {"dark green", {20, 80, 30}},      {"teal", {0, 128, 128}},
    {"turquoise", {60, 200, 190}},  {"sky blue", {135, 195, 235}},     {"light blue", {180, 210, 230}},
    {"steel blue", {70, 130, 180}}, {"blue", {40, 80, 200}},       {"navy", {20, 30, 80}},
    {"purple", {110, 50, 140}},
    {"lavender", {190, 170, 220}},  {"pink", {240, 160, 190}},         {"magenta", {200, 40, 150}},
};

const char *g3d_color_name(const float lab[3])
{
    const char *best = NAMES[0].name;
    double bd = DBL_MAX;
    for (size_t i = 0; i < sizeof NAMES / sizeof NAMES[0]; i++) {
        float rgb[3] = {NAMES[i].rgb[0] / 255.0f, NAMES[i].rgb[1] / 255.0f, NAMES[i].rgb[2] / 255.0f}, l[3];
        g3d_srgb_to_lab(rgb, l);
        double d = 0;
        for (int k = 0; k < 3; k++) d += ((double)l[k] - lab[k]) * ((double)l[k] - lab[k]);
        if (d < bd) bd = d, best = NAMES[i].name;
    }
    return best;
}

/* order[n] = the indices of key[n] by decreasing value; equal values keep their order. */
static void order_desc(const float *key, int n, int *order)
{
    for (int i = 0; i < n; i++) order[i] = i;
    for (int a = 1; a < n; a++)
        for (int b = a; b > 0 && key[order[b]] > key[order[b - 1]]; b--) {
            int t = order[b];
            order[b] = order[b - 1];
            order[b - 1] = t;
        }
}

static double dist2(const float *a, const float *b)
{
    double d = 0;
    for (int k = 0; k < 3; k++) d += ((double)a[k] - b[k]) * ((double)a[k] - b[k]);
    return d;
}

/* k-means++ seeding: the first centre uniformly, each next one with probability proportional
 * to the squared distance to the nearest chosen centre. Returns the centres chosen (fewer
 * than k when every point already coincides with one). */
static int seed_centres(const float *pts, int n, int k, g3d_rng *rng, float *cen, double *d2)
{
    memcpy(cen, pts + 3 * (size_t)g3d_rng_below(rng, (uint32_t)n), sizeof(float) * 3);
    for (int i = 0; i < n; i++) d2[i] = dist2(pts + 3 * (size_t)i, cen);
    int c = 1;
    for (; c < k; c++) {
        double total = 0;
        for (int i = 0; i < n; i++) total += d2[i];
        if (total <= 0) break;
        double r = (double)g3d_rng_float(rng) * total, acc = 0;
        int pick = n - 1;
        for (int i = 0; i < n; i++) {
            acc += d2[i];
            if (acc > r && d2[i] > 0) { pick = i; break; }
        }
        memcpy(cen + 3 * c, pts + 3 * (size_t)pick, sizeof(float) * 3);
        for (int i = 0; i < n; i++) {
            double d = dist2(pts + 3 * (size_t)i, cen + 3 * c);
            if (d < d2[i]) d2[i] = d;
        }
    }
    return c;
}

g3d_status g3d_dominant_colors(const g3d_image *rgb, const g3d_image *exclude, int k, uint64_t seed, g3d_color *out,
                               int *nout)
{
    enum { MAX_POINTS = 65536, MAX_ITER = 100 };
    *nout = 0;
    if (rgb->c != 3 && rgb->c != 1)
        return G3D_ERR(G3D_ERR_ARG, "dominant colours need an RGB or grey image (%d channels given)", rgb->c);
    if (k < 1 || k > G3D_MAX_COLORS) return G3D_ERR(G3D_ERR_ARG, "%d colour clusters: 1 to %d expected", k, G3D_MAX_COLORS);
    if (exclude && (exclude->w != rgb->w || exclude->h != rgb->h || exclude->c != 1))
        return G3D_ERR(G3D_ERR_ARG, "the mask is %dx%dx%d, the image %dx%d", exclude->w, exclude->h, exclude->c, rgb->w, rgb->h);
    size_t total = (size_t)rgb->w * rgb->h, kept = 0;
    for (size_t i = 0; i < total; i++) kept += !exclude || exclude->data[i] < 0.5f;
    if (!kept) return G3D_ERR(G3D_ERR_ARG, "no pixels outside the mask to take colours from");
    size_t stride = (kept + MAX_POINTS - 1) / MAX_POINTS;
    int n = (int)((kept + stride - 1) / stride);
    float *pts = malloc(sizeof(float) * 3 * (size_t)n);
    double *d2 = malloc(sizeof(double) * (size_t)n);
    int *assign = malloc(sizeof(int) * (size_t)n);
    if (!pts || !d2 || !assign) {
        free(pts); free(d2); free(assign);
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    int m = 0;
    for (size_t i = 0, j = 0; i < total; i++) {
        if (exclude && exclude->data[i] >= 0.5f) continue;
        if (j++ % stride) continue;
        const float *v = rgb->data + (size_t)rgb->c * i;
        float px[3] = {v[0], v[rgb->c == 3], v[rgb->c == 3 ? 2 : 0]};
        g3d_srgb_to_lab(px, pts + 3 * (size_t)m++);
    }
    g3d_rng rng;
    g3d_rng_seed(&rng, seed, 0x636f6c6f7572ull);
    float cen[3 * G3D_MAX_COLORS];
    int count[G3D_MAX_COLORS] = {0};
    k = seed_centres(pts, n, k, &rng, cen, d2);
    for (int i = 0; i < n; i++) assign[i] = -1;
    for (int it = 0; it < MAX_ITER; it++) {
        int changed = 0;
        for (int i = 0; i < n; i++) {
            int best = 0;
            double bd = DBL_MAX;
            for (int c = 0; c < k; c++) {
                double d = dist2(pts + 3 * (size_t)i, cen + 3 * c);
                if (d < bd) bd = d, best = c;
            }
            changed += assign[i] != best;
            assign[i] = best;
        }
        double sum[3 * G3D_MAX_COLORS] = {0};
        memset(count, 0, sizeof count);
        for (int i = 0; i < n; i++) {
            count[assign[i]]++;
            for (int d = 0; d < 3; d++) sum[3 * assign[i] + d] += pts[3 * (size_t)i + d];
        }
        for (int c = 0; c < k; c++)
            for (int d = 0; d < 3 && count[c]; d++) cen[3 * c + d] = (float)(sum[3 * c + d] / count[c]);
        if (!changed) break;
    }
    /* by decreasing share; ties keep the seeding order */
    int order[G3D_MAX_COLORS];
    float share[G3D_MAX_COLORS];
    for (int c = 0; c < k; c++) share[c] = (float)count[c];
    order_desc(share, k, order);
    for (int i = 0; i < k && count[order[i]]; i++) {
        g3d_color *o = &out[(*nout)++];
        memcpy(o->lab, cen + 3 * order[i], sizeof o->lab);
        g3d_lab_to_srgb(o->lab, o->rgb);
        o->share = (float)count[order[i]] / (float)n;
        o->name = g3d_color_name(o->lab);
    }
    free(pts);
    free(d2);
    free(assign);
    return G3D_OK;
}

char *g3d_background_prompt(const char *category, const char *const *colors, int n)
{
    size_t len = strlen(category) + 96;
    for (int i = 0; i < n; i++) len += strlen(colors[i]) + 6;
    char *s = malloc(len), *p = s;
    if (!s) return NULL;
    p += sprintf(p, "high-resolution %s background with ", category);
    for (int i = 0; i < n; i++) p += sprintf(p, "%s%s", i == 0 ? "" : i == n - 1 ? " and " : ", ", colors[i]);
    sprintf(p, "%scolors, photorealistic, 8K", n ? " " : "");
    return s;
}

void g3d_description_free(g3d_description *d)
{
    if (!d) return;
    g3d_scene_categories_free(d->category, d->ncat);
    free(d->prob);
    free(d->background_prompt);
    memset(d, 0, sizeof *d);
}

/* The top_k of labels[n] by CLIP zero-shot probability into out->category / prob. */
static g3d_status classify(const g3d_clip *clip, const g3d_clip_tokenizer *tok, const g3d_image *rgb,
                           const char *const *labels, int n, int top_k, g3d_description *out)
{
    int E = g3d_clip_get_config(clip)->embed;
    float *emb = malloc(sizeof(float) * E), *probs = malloc(sizeof(float) * n);
    int *order = malloc(sizeof(int) * n);
    g3d_status rc = emb && probs && order ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = g3d_clip_encode_image(clip, rgb, emb, NULL);
    if (rc == G3D_OK) rc = g3d_clip_zero_shot(clip, tok, emb, labels, n, G3D_SCENE_PROMPT, NULL, probs);
    if (rc == G3D_OK) {
        out->category = calloc((size_t)top_k, sizeof *out->category);
        out->prob = malloc(sizeof(float) * top_k);
        if (!out->category || !out->prob) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    if (rc == G3D_OK) {
        order_desc(probs, n, order);
        for (int i = 0; i < top_k && rc == G3D_OK; i++) {
            out->category[i] = strdup(labels[order[i]]);
            out->prob[i] = probs[order[i]];
            out->ncat = i + 1;
            if (!out->category[i]) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        }
    }
    free(emb);
    free(probs);
    free(order);
    return rc;
}

cJSON *g3d_description_json(const g3d_description *d)
{
    cJSON *j = cJSON_CreateObject(), *cats = cJSON_AddArrayToObject(j, "categories"), *cols = cJSON_AddArrayToObject(j, "colors");
    for (int i = 0; cats && i < d->ncat; i++) {
        cJSON *c = cJSON_CreateObject();
        cJSON_AddStringToObject(c, "label", d->category[i]);
        cJSON_AddNumberToObject(c, "probability", round(d->prob[i] * 1e6) / 1e6);
        cJSON_AddItemToArray(cats, c);
    }
    for (int i = 0; cols && i < d->ncolors; i++) {
        const g3d_color *c = &d->colors[i];
        char hex[8];
        snprintf(hex, sizeof hex, "#%02x%02x%02x", (int)lrintf(c->rgb[0] * 255), (int)lrintf(c->rgb[1] * 255),
                 (int)lrintf(c->rgb[2] * 255));
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "name", c->name);
        cJSON_AddStringToObject(o, "rgb", hex);
        cJSON_AddNumberToObject(o, "share", round(c->share * 1e4) / 1e4);
        cJSON_AddItemToArray(cols, o);
    }
    if (d->background_prompt) cJSON_AddStringToObject(j, "background_prompt", d->background_prompt);
    if (!cats || !cols) {
        cJSON_Delete(j);
        return NULL;
    }
    return j;
}

g3d_status g3d_describe_scene(const g3d_clip *clip, const g3d_clip_tokenizer *tok, const g3d_image *rgb,
                              const g3d_image *exclude, const char *const *labels, int n, int top_k, uint64_t seed,
                              g3d_description *out)
{
    memset(out, 0, sizeof *out);
    if (!labels) labels = g3d_scene_categories(&n);
    if (top_k < 1) return G3D_ERR(G3D_ERR_ARG, "top-k must be at least 1");
    if (top_k > n) top_k = n;
    g3d_status rc = clip ? classify(clip, tok, rgb, labels, n, top_k, out) : G3D_OK;
    if (rc == G3D_OK) rc = g3d_dominant_colors(rgb, exclude, 5, seed, out->colors, &out->ncolors);
    if (rc == G3D_OK) {
        const char *names[G3D_TEMPLATE_COLORS];
        int nn = 0;
        for (int i = 0; i < out->ncolors && nn < G3D_TEMPLATE_COLORS; i++) {
            int seen = 0;
            for (int j = 0; j < nn; j++) seen |= !strcmp(names[j], out->colors[i].name);
            if (!seen) names[nn++] = out->colors[i].name;
        }
        if (!(out->background_prompt = g3d_background_prompt(out->ncat ? out->category[0] : "scene", names, nn)))
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    if (rc != G3D_OK) g3d_description_free(out);
    return rc;
}

g3d_status g3d_describe_tokenizer_load(const char *clip_model, const char *tokenizer, g3d_clip_tokenizer **out)
{
    struct stat st;
    char *v = !tokenizer && clip_model && stat(clip_model, &st) == 0 && S_ISDIR(st.st_mode) ? g3d_path_join(clip_model, "vocab.json")
                                                                                             : NULL;
    int own = v && stat(v, &st) == 0;
    free(v);
    return g3d_clip_tokenizer_load(tokenizer ? tokenizer : own ? clip_model : NULL, out);
}

typedef struct describer {
    g3d_clip *clip;
    g3d_clip_tokenizer *tok;
    g3d_blip *blip;
    uint64_t seed;
} describer;

static void describer_free(void *ctx)
{
    describer *d = ctx;
    g3d_clip_free(d->clip);
    g3d_clip_tokenizer_free(d->tok);
    g3d_blip_free(d->blip);
    free(d);
}

static g3d_status describer_prompt(void *ctx, const g3d_image *rgb, const g3d_image *exclude, char **background, char **view)
{
    describer *dd = ctx;
    g3d_description d;
    *background = *view = NULL;
    G3D_TRY(g3d_describe_scene(dd->clip, dd->tok, rgb, exclude, NULL, 0, 1, dd->seed, &d));
    if (d.ncat) g3d_log(G3D_LOG_INFO, "scene category: %s (%.3f)", d.category[0], d.prob[0]);
    *background = d.background_prompt;
    d.background_prompt = NULL;
    g3d_description_free(&d);
    g3d_status rc = G3D_OK;
    if (dd->blip) {
        g3d_blip_gen g;
        g3d_blip_gen_default(&g);
        rc = g3d_blip_caption(dd->blip, rgb, &g, view);
    }
    if (rc != G3D_OK) {
        free(*background);
        *background = NULL;
    }
    return rc;
}

g3d_status g3d_prompt_provider_describe_create(const char *clip_model, const char *tokenizer, const char *caption_model,
                                               uint64_t seed, g3d_prompt_provider *out)
{
    memset(out, 0, sizeof *out);
    describer *d = calloc(1, sizeof *d);
    if (!d) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    d->seed = seed;
    g3d_status rc = clip_model ? g3d_clip_load(clip_model, &d->clip) : G3D_OK;
    if (rc == G3D_OK && clip_model) rc = g3d_describe_tokenizer_load(clip_model, tokenizer, &d->tok);
    if (rc == G3D_OK && caption_model) rc = g3d_blip_load(caption_model, &d->blip);
    if (rc != G3D_OK) {
        describer_free(d);
        return rc;
    }
    *out = (g3d_prompt_provider){.name = d->blip ? (d->clip ? "clip+blip" : "colours+blip") : d->clip ? "clip" : "colours",
                                 .ctx = d, .prompt = describer_prompt, .free = describer_free};
    return G3D_OK;
}
