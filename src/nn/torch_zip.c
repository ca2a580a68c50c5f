/* torch_zip.c - PyTorch zip checkpoints (torch.save since 1.6). */
#include "ckpt_int.h"

g3d_status g3d__torch_zip_parse(g3d_ckpt *ck)
{
    return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: PyTorch zip checkpoints are not supported yet", ck->path);
}
