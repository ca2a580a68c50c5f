# PyTorch twin of bench_depth.c: a Depth Anything V2 ViT-S of the same layer structure
# (DINOv2 ViT-S/14 + DPT head, random weights: the cost does not depend on values), timed one
# forward per request so that the two programs alternate.
#   /usr/bin/python3 bench/bench_depth_torch.py [size=518] [threads=2]
# Prints "ready" once built; then for every line read from stdin runs one size x size forward
# and prints "torch_seconds <wall s> <CPU s of all threads>".
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

size = int(sys.argv[1]) if len(sys.argv) > 1 else 518
threads = int(sys.argv[2]) if len(sys.argv) > 2 else 2
torch.set_num_threads(threads)
D, HEADS, DEPTH, FEAT = 384, 6, 12, 64
OC = [48, 96, 192, 384]
LAYERS = [2, 5, 8, 11]


class Block(nn.Module):
    def __init__(self):
        super().__init__()
        self.norm1, self.norm2 = nn.LayerNorm(D, eps=1e-6), nn.LayerNorm(D, eps=1e-6)
        self.qkv, self.proj = nn.Linear(D, 3 * D), nn.Linear(D, D)
        self.fc1, self.fc2 = nn.Linear(D, 4 * D), nn.Linear(4 * D, D)
        self.ls1, self.ls2 = nn.Parameter(torch.ones(D)), nn.Parameter(torch.ones(D))

    def forward(self, x):
        n = x.shape[1]
        q, k, v = self.qkv(self.norm1(x)).reshape(1, n, 3, HEADS, D // HEADS).permute(2, 0, 3, 1, 4)
        a = torch.softmax(q @ k.transpose(-2, -1) * (D // HEADS) ** -0.5, dim=-1)
        x = x + self.ls1 * self.proj((a @ v).transpose(1, 2).reshape(1, n, D))
        return x + self.ls2 * self.fc2(F.gelu(self.fc1(self.norm2(x))))


class RCU(nn.Module):
    def __init__(self):
        super().__init__()
        self.c1, self.c2 = nn.Conv2d(FEAT, FEAT, 3, padding=1), nn.Conv2d(FEAT, FEAT, 3, padding=1)

    def forward(self, x):
        return self.c2(F.relu(self.c1(F.relu(x)))) + x


class Fusion(nn.Module):
    def __init__(self):
        super().__init__()
        self.r1, self.r2, self.out = RCU(), RCU(), nn.Conv2d(FEAT, FEAT, 1)

    def forward(self, x, skip=None, size=None):
        if skip is not None:
            x = x + self.r1(skip)
        x = self.r2(x)
        x = F.interpolate(x, size=size, mode="bilinear", align_corners=True) if size else \
            F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=True)
        return self.out(x)


class Model(nn.Module):
    def __init__(self):
        super().__init__()
        self.patch = nn.Conv2d(3, D, 14, 14)
        self.cls, self.pos = nn.Parameter(torch.zeros(1, 1, D)), nn.Parameter(torch.zeros(1, 1370, D))
        self.blocks = nn.ModuleList(Block() for _ in range(DEPTH))
        self.norm = nn.LayerNorm(D, eps=1e-6)
        self.projects = nn.ModuleList(nn.Conv2d(D, c, 1) for c in OC)
        self.resize = nn.ModuleList([nn.ConvTranspose2d(48, 48, 4, 4), nn.ConvTranspose2d(96, 96, 2, 2),
                                     nn.Identity(), nn.Conv2d(384, 384, 3, 2, 1)])
        self.rn = nn.ModuleList(nn.Conv2d(c, FEAT, 3, padding=1, bias=False) for c in OC)
        self.fuse = nn.ModuleList(Fusion() for _ in range(4))
        self.out1 = nn.Conv2d(FEAT, FEAT // 2, 3, padding=1)
        self.out2 = nn.Sequential(nn.Conv2d(FEAT // 2, 32, 3, padding=1), nn.ReLU(), nn.Conv2d(32, 1, 1), nn.ReLU())

    def forward(self, img):
        h, w = img.shape[2] // 14, img.shape[3] // 14
        x = self.patch(img).flatten(2).transpose(1, 2)
        pos = F.interpolate(self.pos[:, 1:].reshape(1, 37, 37, D).permute(0, 3, 1, 2), mode="bicubic",
                            scale_factor=((h + 0.1) / 37, (w + 0.1) / 37), align_corners=False)
        x = torch.cat([self.cls, x + pos.permute(0, 2, 3, 1).reshape(1, -1, D)], 1)
        feats = []
        for i, b in enumerate(self.blocks):
            x = b(x)
            if i in LAYERS:
                feats.append(self.norm(x)[:, 1:])
        ls = []
        for i, f in enumerate(feats):
            f = f.permute(0, 2, 1).reshape(1, D, h, w)
            ls.append(self.rn[i](self.resize[i](self.projects[i](f))))
        p = self.fuse[3](ls[3], size=ls[2].shape[2:])
        p = self.fuse[2](p, ls[2], size=ls[1].shape[2:])
        p = self.fuse[1](p, ls[1], size=ls[0].shape[2:])
        p = self.fuse[0](p, ls[0])
        p = F.interpolate(self.out1(p), (h * 14, w * 14), mode="bilinear", align_corners=True)
        return self.out2(p)


model = Model().eval()
img = torch.randn(1, 3, size, size)
print("ready", flush=True)
with torch.no_grad():
    for line in sys.stdin:
        t0, c0 = time.time(), time.process_time()
        model(img)
        print("torch_seconds %.4f %.4f" % (time.time() - t0, time.process_time() - c0), flush=True)
