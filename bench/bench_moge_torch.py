# PyTorch twin of bench_moge.c --twin: the official MoGe-2 model (microsoft/MoGe at 0744441,
# moge/model/v2.py MoGeModel, imported unchanged with the stand-ins of
# tests/fixtures/make_moge_golden.py for what torch 1.13 lacks) built from the same checkpoint
# gen3d loads, timed one forward per request so that the two programs alternate.
#   /usr/bin/python3 bench/bench_moge_torch.py MOGE_CHECKOUT UTILS3D_CHECKOUT MODEL.pt [tokens=2500]
#       [threads=2] [width=640] [height=480]
# Prints "ready" once built; then for every line read from stdin runs model(image, num_tokens) on
# one width x height picture and prints "torch_seconds <wall s> <CPU s of all threads>".
import os
import sys
import time

import torch

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "tests", "fixtures"))
import golden_util as gu  # noqa: E402

src = gu.checkout(1, "MOGE_CHECKOUT", "microsoft/MoGe", "0744441")
u3d = gu.checkout(2, "UTILS3D_CHECKOUT", "EasternJournalist/utils3d", "3fab839")
path = sys.argv[3]
tokens, threads, W, H = (int(sys.argv[i]) if len(sys.argv) > i else d for i, d in ((4, 2500), (5, 2), (6, 640), (7, 480)))
sys.path[:0] = [src, u3d]
torch.set_num_threads(threads)
torch.set_grad_enabled(False)
gu.moge_torch113_compat()
from moge.model import v2  # noqa: E402  (needs the stand-ins)

ck = torch.load(path, map_location="cpu")
model = v2.MoGeModel(**ck["model_config"]).eval()
model.load_state_dict({k: v.float() for k, v in ck["model"].items()})
image = torch.rand(1, 3, H, W, generator=torch.Generator().manual_seed(1))
print("ready", flush=True)
for line in sys.stdin:
    t0, c0 = time.time(), time.process_time()
    model(image, num_tokens=tokens)
    print("torch_seconds %.4f %.4f" % (time.time() - t0, time.process_time() - c0), flush=True)
