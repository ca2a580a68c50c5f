# PyTorch twin of bench_lama.c: the official big-lama generator (advimman/lama's
# FFCResNetGenerator as configs/training/big-lama.yaml builds it, imported from a checkout of
# the repository; random weights: the cost does not depend on values), saved as a state dict
# for the C side to load, then timed one forward per request so that the two alternate.
#   /usr/bin/python3 bench/bench_lama_torch.py CHECKOUT SAVE_PATH [size=512] [threads=2]
# Prints "ready" once SAVE_PATH is written; then for every line read from stdin runs one
# size x size forward and prints "torch_seconds <wall s> <CPU s of all threads>".
import os
import sys
import time

import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures"))
import golden_util as gu

src = gu.checkout(1, "LAMA_CHECKOUT", "advimman/lama", "786f593")
save = sys.argv[2]
size = int(sys.argv[3]) if len(sys.argv) > 3 else 512
threads = int(sys.argv[4]) if len(sys.argv) > 4 else 2
torch.set_num_threads(threads)
torch.manual_seed(0)
ffc = gu.lama_ffc(src)
no_lfu = dict(enable_lfu=False)
net = ffc.FFCResNetGenerator(input_nc=4, output_nc=3, ngf=64, n_downsampling=3, n_blocks=18, add_out_act="sigmoid",
                             init_conv_kwargs=dict(ratio_gin=0, ratio_gout=0, **no_lfu),
                             downsample_conv_kwargs=dict(ratio_gin=0, ratio_gout=0, **no_lfu),
                             resnet_conv_kwargs=dict(ratio_gin=0.75, ratio_gout=0.75, **no_lfu)).eval()
torch.save({"state_dict": {"generator." + k: v.contiguous() for k, v in net.state_dict().items()}}, save)
x = torch.rand(1, 4, size, size)
x[:, 3] = (x[:, 3] > 0.5).float()
print("ready", flush=True)
with torch.no_grad():
    for line in sys.stdin:
        t0, c0 = time.time(), time.process_time()
        net(x)
        print("torch_seconds %.4f %.4f" % (time.time() - t0, time.process_time() - c0), flush=True)
