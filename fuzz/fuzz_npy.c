/* libFuzzer target: the .npy parser (header dictionary, dtype, shape, data size). */
#include "gen3d/npy.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    g3d_array a;
    if (g3d_npy_parse(data, size, "fuzz.npy", &a) == G3D_OK) g3d_array_free(&a);
    return 0;
}
