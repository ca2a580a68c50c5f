#!/bin/sh
# gen3d info on Stable Diffusion checkpoints: the family and configuration, read from the files.
set -u
T="$G3D_TEST_TMP/cli_sd"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

expect 0 "info names an SD 1.x UNet" "$GEN3D" info "$FIX/sdunet_sd1_tiny.ckpt"
grep -q "SD 1.x UNet (4 input channels, model channels 32, multipliers 1/1/1, res blocks 2/2/2, attention at levels 0/1.*context 48, 8 heads, 1x1-conv" "$T/out" \
    && ok "SD 1.x configuration" || bad "info: $(head -1 "$T/out")"
expect 0 "info names an SD 2.x inpainting UNet" "$GEN3D" info "$FIX/sdunet_sd2_tiny.safetensors"
grep -q "SD 2.x UNet (9 input channels: inpainting.*multipliers 1/1/2.*context 64, heads of 16, Linear projections, v prediction" "$T/out" \
    && ok "SD 2.x configuration" || bad "info: $(head -1 "$T/out")"
expect 0 "info names the VAE" "$GEN3D" info "$FIX/sdunet_vae_tiny.safetensors"
grep -q "Stable Diffusion VAE (channels 32, multipliers 1/2, 1 res blocks, 4 latent channels" "$T/out" \
    && ok "VAE configuration" || bad "info: $(head -1 "$T/out")"
finish
