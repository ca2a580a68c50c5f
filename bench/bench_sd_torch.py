# PyTorch twin of bench_sd.c: the official SD 1.5 UNet (ldm's UNetModel with the configuration of
# v1-inference.yaml) and VAE decoder (AutoencoderKL, ch 128, 1/2/4/4) with random weights (the cost
# does not depend on the values), timed on the CPU with the given thread count:
#   one denoising step at 512 x 512 = the UNet on a batch of 2 (guidance) 64 x 64 latents with a
#   77 x 768 context; the VAE decoding of one 64 x 64 latent to 512 x 512.
# Also counts the multiply-adds of both (Conv2d, Linear, attention products) with forward hooks.
#   /usr/bin/python3 bench/bench_sd_torch.py STABLEDIFFUSION_CHECKOUT [threads=2] [reps=1] [--write FILE.safetensors]
#       [--vae-only]
# Prints "torch_unet_seconds S C", "torch_vae_seconds S C" (wall and CPU seconds of all threads, best
# of reps by wall), "unet_gflop G" (batch 2), "vae_gflop G"; --vae-only builds and times only the VAE
# decoder; --write saves the weights (fp16, model.diffusion_model.* and first_stage_model.*) for
# bench_sd.c.
# The official code comes from a checkout of github.com/Stability-AI/stablediffusion (cf1d67a),
# imported unchanged as tests/fixtures/make_sdunet_golden.py does.
import os
import sys
import time

import torch

here = os.path.dirname(os.path.abspath(__file__))
args = [a for a in sys.argv[1:] if not a.startswith("--")]
vae_only = "--vae-only" in sys.argv and "--write" not in sys.argv
write = sys.argv[sys.argv.index("--write") + 1] if "--write" in sys.argv else None
if write in args:
    args.remove(write)
threads = int(args[1]) if len(args) > 1 else 2
reps = int(args[2]) if len(args) > 2 else 1
sys.argv = [sys.argv[0], args[0]]
sys.path.insert(0, os.path.join(here, "..", "tests", "fixtures"))
import golden_util as gu  # noqa: E402
import make_sdunet_golden as ldm  # noqa: E402  (the official modules, with its stand-ins)

torch.set_num_threads(threads)
torch.set_grad_enabled(False)
torch.manual_seed(0)
unet = None if vae_only else ldm.UNetModel(image_size=32, in_channels=4, out_channels=4, model_channels=320, attention_resolutions=[4, 2, 1],
                     num_res_blocks=2, channel_mult=[1, 2, 4, 4], num_heads=8, use_spatial_transformer=True,
                     transformer_depth=1, context_dim=768, use_checkpoint=False, legacy=False).eval()
vae = ldm.AutoencoderKL(dict(double_z=True, z_channels=4, resolution=256, in_channels=3, out_ch=3, ch=128, ch_mult=[1, 2, 4, 4],
                             num_res_blocks=2, attn_resolutions=[], dropout=0.0), {}, embed_dim=4).eval()
for p in (list(unet.parameters()) if unet else []) + list(vae.parameters()):
    if p.dim() > 1:
        p.normal_(0, p[0].numel() ** -0.5)   # zero-initialised output layers would make no difference to the time either
if write:
    t = {"model.diffusion_model." + k: v.numpy() for k, v in gu.half_state_dict(unet).items()}
    t.update({"first_stage_model." + k: v.numpy() for k, v in gu.half_state_dict(vae).items()})
    gu.write_safetensors(write, t, {"model": "SD 1.5 UNet and VAE, random weights (bench)"})
    del t

flops = {"n": 0}


def count(mod, inp, out):
    if isinstance(mod, torch.nn.Conv2d):
        flops["n"] += 2 * out.numel() * mod.in_channels // mod.groups * mod.kernel_size[0] * mod.kernel_size[1]
    elif isinstance(mod, torch.nn.Linear):
        flops["n"] += 2 * out.numel() * mod.in_features
    elif type(mod).__name__ == "CrossAttention":
        x, ctx = inp[0], (inp[1] if len(inp) > 1 and inp[1] is not None else inp[0])
        flops["n"] += 4 * x.shape[0] * x.shape[1] * ctx.shape[1] * mod.to_q.out_features
    elif type(mod).__name__ == "AttnBlock":
        b, c, h, w = inp[0].shape
        flops["n"] += 4 * b * (h * w) ** 2 * c


hooks = [m.register_forward_hook(count) for m in (list(unet.modules()) if unet else []) + list(vae.modules())]
x = torch.randn(2, 4, 64, 64)
ctx = torch.randn(2, 77, 768)
ts = torch.tensor([981.0, 981.0])
best_u = best_v = (1e30, 0)
fu = 0
for r in range(reps):
    if unet:
        flops["n"] = 0
        t0, c0 = time.time(), time.process_time()
        unet(x, timesteps=ts, context=ctx)
        best_u = min(best_u, (time.time() - t0, time.process_time() - c0))
        fu = flops["n"]
    flops["n"] = 0
    t0, c0 = time.time(), time.process_time()
    vae.decode(x[:1])
    best_v = min(best_v, (time.time() - t0, time.process_time() - c0))
    fv = flops["n"]
if unet:
    print("torch_unet_seconds %.3f %.3f" % best_u)
    print("unet_gflop %.2f" % (fu * 1e-9))
print("torch_vae_seconds %.3f %.3f" % best_v)
print("vae_gflop %.2f" % (fv * 1e-9))
import resource  # noqa: E402
print("torch_peak_gb %.2f" % (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1048576))
