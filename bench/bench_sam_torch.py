# PyTorch twin of bench_sam.c: the official Segment Anything ViT-B (build_sam_vit_b of
# facebookresearch/segment-anything, imported from a checkout; random weights: the cost does not
# depend on values), saved as a state dict for the C side to load, then its image encoder timed
# one 1024 x 1024 forward per request so that the two alternate.
#   /usr/bin/python3 bench/bench_sam_torch.py CHECKOUT SAVE_PATH [threads=2]
# Prints "ready" once SAVE_PATH is written; then for every line read from stdin runs one forward
# and prints "torch_seconds <wall s> <CPU s of all threads>".
import os
import sys
import time

import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures"))
import golden_util as gu

src = gu.checkout(1, "SAM_CHECKOUT", "facebookresearch/segment-anything", "dca509f")
save = sys.argv[2]
threads = int(sys.argv[3]) if len(sys.argv) > 3 else 2
torch.set_num_threads(threads)
torch.manual_seed(0)
# torchvision is not in Debian; the model never calls these
gu.stub_module("torchvision.transforms.functional", resize=None, to_pil_image=None)
gu.stub_module("torchvision.ops.boxes", batched_nms=None, box_area=None)
sys.path.insert(0, src)
from segment_anything import sam_model_registry  # noqa: E402

sam = sam_model_registry["vit_b"]().eval()
torch.save({k: v.contiguous() for k, v in sam.state_dict().items()}, save)
x = torch.randn(1, 3, 1024, 1024)
print("ready", flush=True)
with torch.no_grad():
    for line in sys.stdin:
        t0, c0 = time.time(), time.process_time()
        sam.image_encoder(x)
        print("torch_seconds %.4f %.4f" % (time.time() - t0, time.process_time() - c0), flush=True)
