// Cameras as gen3d writes them into the page: pinhole intrinsics of a w x h image in pixels
// (fx, fy, cx, cy; pixel centres at integer coordinates, as OpenCV) and `c2w`, a row-major
// 4x4 camera-to-world matrix already in three.js axes (x right, y up, z towards the viewer).
import * as THREE from 'three';

export function cameraPose(cam) {
  const m = new THREE.Matrix4().set(...cam.c2w);
  const position = new THREE.Vector3();
  const quaternion = new THREE.Quaternion();
  m.decompose(position, quaternion, new THREE.Vector3());
  return { position, quaternion, K: { w: cam.w, h: cam.h, fx: cam.fx, fy: cam.fy, cx: cam.cx, cy: cam.cy } };
}

// A pose between a (t = 0) and b (t = 1): positions and intrinsics linearly, rotations by slerp.
export function blendPose(a, b, t) {
  const mix = (x, y) => x + (y - x) * t;
  return {
    position: a.position.clone().lerp(b.position, t),
    quaternion: a.quaternion.clone().slerp(b.quaternion, t),
    K: { w: mix(a.K.w, b.K.w), h: mix(a.K.h, b.K.h), fx: mix(a.K.fx, b.K.fx), fy: mix(a.K.fy, b.K.fy),
         cx: mix(a.K.cx, b.K.cx), cy: mix(a.K.cy, b.K.cy) },
  };
}

// The projection that shows the camera's whole w x h image as large as fits in the canvas,
// centred, with its principal point where the camera has it, and the focal lengths times
// `zoom`. With a canvas of exactly w x h pixels and zoom 1 each canvas pixel sees what pixel
// (i, j) of the camera sees: continuous image coordinate u lands at canvas x = u + 0.5.
export function setProjection(camera, K, canvasW, canvasH, zoom, near, far) {
  const s = Math.min(canvasW / K.w, canvasH / K.h);
  const offX = (canvasW - s * K.w) / 2, offY = (canvasH - s * K.h) / 2;
  const px = (2 / canvasW) * (offX + s * (K.cx + 0.5)) - 1;
  const py = 1 - (2 / canvasH) * (offY + s * (K.cy + 0.5));
  const sx = (2 * s * zoom * K.fx) / canvasW, sy = (2 * s * zoom * K.fy) / canvasH;
  camera.projectionMatrix.set(
    sx, 0, -px, 0,
    0, sy, -py, 0,
    0, 0, -(far + near) / (far - near), (-2 * far * near) / (far - near),
    0, 0, -1, 0);
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  // kept in step for code that reads them (OrbitControls pans by the vertical field of view)
  camera.fov = THREE.MathUtils.radToDeg(2 * Math.atan(1 / sy));
  camera.aspect = canvasW / canvasH;
  camera.near = near;
  camera.far = far;
  return camera.fov;
}
