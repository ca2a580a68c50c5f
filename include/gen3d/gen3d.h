/* gen3d/gen3d.h - the whole public API in one include.
 *
 * Most programs need only g3d_generate (generate.h): one input to a trained Gaussian-splat
 * scene. The stages it chains are public too, one header per module:
 *
 *   base        status codes and messages, logging, progress and cancelling, RNG, atomic files
 *   io          image files (imageio), depth maps (depthio), NumPy arrays (npy), zip, PLY,
 *               camera files (cameras_json), resampling (resize), video
 *   geom        cameras and transforms (camera), camera paths (trajectory), pinhole cameras
 *               from point maps (pointmap)
 *   input       the input frame (frame), the procedural test room (procscene)
 *   world       the cloud (cloud), depth alignment (align), layers, the world loop (world),
 *               dataset folders (dataset)
 *   classic     weight-free plug-ins: inpainting (inpaint_classic), depth completion
 *               (depth_complete), object proposals (regions), harmonic fill (membrane)
 *   nn, models  checkpoints (ckpt), operators (nn), model recognition (recognize), DINOv2,
 *               Depth Anything V2, MoGe-2, depth fitting (depthfit), the depth-estimator
 *               plug-ins on them (depth_estimators)
 *   splat       Gaussians, initialisation (init), rasterizer (raster), loss, Adam, densify,
 *               training (train), rendering along paths (render), .spz
 *   pipeline    the chain (generate)
 *   batch       many scenes: manifests, the batch folder and its status files, shards, the
 *               Slurm job-array script (batch)
 *
 * The plug-in tables every stage takes are in providers.h. Conventions: camera.h (axes,
 * poses, pixel centres) and image.h (layouts, depth in metres with 0 = invalid).
 */
#ifndef G3D_GEN3D_H
#define G3D_GEN3D_H

#include "gen3d/base.h"

#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/image.h"
#include "gen3d/imageio.h"
#include "gen3d/npy.h"
#include "gen3d/ply.h"
#include "gen3d/resize.h"
#include "gen3d/video.h"
#include "gen3d/zip.h"

#include "gen3d/camera.h"
#include "gen3d/pointmap.h"
#include "gen3d/trajectory.h"

#include "gen3d/frame.h"
#include "gen3d/procscene.h"

#include "gen3d/align.h"
#include "gen3d/cloud.h"
#include "gen3d/dataset.h"
#include "gen3d/layers.h"
#include "gen3d/providers.h"
#include "gen3d/world.h"

#include "gen3d/depth_complete.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/membrane.h"
#include "gen3d/regions.h"

#include "gen3d/blip.h"
#include "gen3d/ckpt.h"
#include "gen3d/clip.h"
#include "gen3d/depth_anything.h"
#include "gen3d/depth_estimators.h"
#include "gen3d/depthfit.h"
#include "gen3d/describe.h"
#include "gen3d/dinov2.h"
#include "gen3d/moge.h"
#include "gen3d/nn.h"
#include "gen3d/recognize.h"

#include "gen3d/adam.h"
#include "gen3d/densify.h"
#include "gen3d/explore.h"
#include "gen3d/gaussians.h"
#include "gen3d/init.h"
#include "gen3d/loss.h"
#include "gen3d/raster.h"
#include "gen3d/render.h"
#include "gen3d/spz.h"
#include "gen3d/train.h"

#include "gen3d/generate.h"

#include "gen3d/batch.h"

#endif /* G3D_GEN3D_H */
