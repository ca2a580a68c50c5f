/* Sinusoidal embeddings. */
#include "nn/nn_int.h"

#include <math.h>

void g3d_nn_timestep_embedding(float t, int dim, float max_period, float *out)
{
    const int half = dim / 2;
    for (int j = 0; j < half; j++) {
        /* float32 like the reference: exp(-ln(P) * j / half) then t * f */
        float f = expf(-logf(max_period) * (float)j / (float)half), a = t * f;
        out[j] = cosf(a);
        out[half + j] = sinf(a);
    }
    if (dim % 2) out[dim - 1] = 0.0f;
}
