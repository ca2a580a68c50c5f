/* Shards of a manifest: scene i belongs to shard i mod N, from --shard K/N or a Slurm array. */
#include "gen3d/batch.h"

#include <errno.h>
#include <stdlib.h>

static int parse_int(const char *s, long *v)
{
    char *end;
    if (!s || !*s) return -1;
    errno = 0;
    *v = strtol(s, &end, 10);
    return errno || *end || *v < 0 || *v > 1000000000L ? -1 : 0;
}

g3d_status g3d_batch_shard_parse(const char *text, int *k, int *n)
{
    long a, b;
    const char *slash = text;
    while (*slash && *slash != '/') slash++;
    char head[32];
    size_t len = (size_t)(slash - text);
    if (*slash != '/' || len == 0 || len >= sizeof head)
        return G3D_ERR(G3D_ERR_ARG, "shard '%s': expected K/N with 0 <= K < N", text);
    for (size_t i = 0; i < len; i++) head[i] = text[i];
    head[len] = 0;
    if (parse_int(head, &a) || parse_int(slash + 1, &b) || b < 1 || a >= b)
        return G3D_ERR(G3D_ERR_ARG, "shard '%s': expected K/N with 0 <= K < N", text);
    *k = (int)a;
    *n = (int)b;
    return G3D_OK;
}

int g3d_batch_shard_from_env(int *k, int *n)
{
    long id, lo = 0, hi, count;
    *k = 0;
    *n = 1;
    if (parse_int(getenv("SLURM_ARRAY_TASK_ID"), &id)) return 0;
    if (getenv("SLURM_ARRAY_TASK_MIN") && parse_int(getenv("SLURM_ARRAY_TASK_MIN"), &lo)) return -1;
    if (parse_int(getenv("SLURM_ARRAY_TASK_COUNT"), &count)) {
        if (parse_int(getenv("SLURM_ARRAY_TASK_MAX"), &hi) || hi < lo) return -1;
        count = hi - lo + 1;
    }
    if (count < 1 || id < lo || id - lo >= count) return -1;
    *k = (int)(id - lo);
    *n = (int)count;
    return 1;
}

int g3d_batch_in_shard(int index, int k, int n)
{
    return n <= 1 || index % n == k;
}
