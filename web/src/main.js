// The gen3d scene viewer: three.js + Spark render the embedded .spz; the page opens at the
// input camera with its intrinsics; orbit/pan/zoom with the mouse or touch, fly with the
// keyboard, play the generation and video paths. boot.js starts it and provides window.g3d,
// whose fields (ready, error, frames) let scripts driving a browser see the page's state.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { SparkRenderer, SplatMesh } from '@sparkjsdev/spark';
import { readConfig, readScene } from './embedded.js';
import { cameraPose, blendPose, setProjection } from './camera.js';

const state = window.g3d;
const $ = (id) => document.getElementById(id);

function makeRenderer() {
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: false });
  } catch (e) {
    throw new Error('This browser cannot show the scene: WebGL 2 is not available or is turned off.');
  }
  renderer.setPixelRatio(window.devicePixelRatio);
  renderer.setSize(window.innerWidth, window.innerHeight);
  renderer.domElement.tabIndex = 0;
  document.body.prepend(renderer.domElement);
  return renderer;
}

// Splats drawn as gen3d's own rasterizer draws them: 0.3 px^2 added to every projected
// covariance without opacity compensation, each splat cut where its alpha falls below
// 1/255 (at most sqrt(2 ln 255) = 3.33 standard deviations), sorted by view depth, full
// precision for positions, scales and colours (the extended encoding).
function makeSpark(renderer) {
  return new SparkRenderer({
    renderer,
    preBlurAmount: 0.3,
    blurAmount: 0,
    maxStdDev: Math.sqrt(2 * Math.log(255)),
    minAlpha: 1 / 255,
    sortRadial: false,
    enableLod: false,
    accumExtSplats: true,
  });
}

async function loadMesh(bytes, config) {
  const mesh = new SplatMesh({ fileBytes: bytes, fileName: 'scene.spz', extSplats: true });
  try {
    await mesh.initialized;
  } catch (e) {
    throw new Error(`The scene in this page could not be decoded (${e && e.message ? e.message : e}).`);
  }
  if (mesh.numSplats !== config.scene.gaussians)
    throw new Error(`The scene in this page decoded to ${mesh.numSplats} Gaussians instead of ${config.scene.gaussians}.`);
  return mesh;
}

async function main() {
  const config = readConfig();
  const bytes = await readScene(config);

  const renderer = makeRenderer();
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0, 0, 0);
  scene.add(makeSpark(renderer));
  const mesh = await loadMesh(bytes, config);
  scene.add(mesh);
  state.gaussians = mesh.numSplats;

  const scale = config.scene.scale > 0 ? config.scene.scale : 1;
  const near = 0.01, far = Math.max(1000, 1000 * scale);
  const camera = new THREE.PerspectiveCamera();
  const input = cameraPose(config.input);
  let K = input.K;
  let zoom = 1;

  const controls = new OrbitControls(camera, renderer.domElement);
  controls.zoomToCursor = true;
  const forward = new THREE.Vector3();
  function setPose(pose) {
    camera.position.copy(pose.position);
    camera.quaternion.copy(pose.quaternion);
    camera.updateMatrixWorld();
    K = pose.K;
    // orbit about the point one scene scale ahead (the input view's median depth)
    forward.set(0, 0, -1).applyQuaternion(camera.quaternion);
    controls.target.copy(camera.position).addScaledVector(forward, scale);
  }

  function project() {
    const fov = setProjection(camera, K, window.innerWidth, window.innerHeight, zoom, near, far);
    $('fov-value').textContent = `${fov.toFixed(1)}\u00b0`;
  }

  // paths: a list of cameras played at `fps` cameras per second, blended in between
  let playing = null;
  const paths = {};
  for (const p of config.paths || []) if (p.cameras && p.cameras.length) paths[p.name] = p;
  function play(name) {
    const p = paths[name];
    if (!p) return;
    playing = { poses: p.cameras.map(cameraPose), fps: p.fps > 0 ? p.fps : 1, t0: performance.now() };
    $('status').textContent = `playing the ${name} path (${p.cameras.length} cameras); any key or drag stops`;
  }
  function stop() {
    if (!playing) return;
    playing = null;
    $('status').textContent = '';
  }
  function advance(now) {
    // a frame's timestamp may precede the key press that started the path
    const f = Math.max(0, ((now - playing.t0) / 1000) * playing.fps), last = playing.poses.length - 1;
    const i = Math.min(Math.floor(f), last), t = Math.min(f - i, 1);
    setPose(i >= last ? playing.poses[last] : blendPose(playing.poses[i], playing.poses[i + 1], t));
    if (f >= last) stop();
  }
  function reset() {
    stop();
    zoom = 1;
    $('fov').value = 0;
    setPose(input);
  }

  // keyboard flight in the camera's own frame; the orbit centre travels along
  const keys = new Set();
  const moves = {
    KeyW: [0, 0, -1], ArrowUp: [0, 0, -1], KeyS: [0, 0, 1], ArrowDown: [0, 0, 1],
    KeyA: [-1, 0, 0], ArrowLeft: [-1, 0, 0], KeyD: [1, 0, 0], ArrowRight: [1, 0, 0],
    KeyQ: [0, -1, 0], KeyE: [0, 1, 0],
  };
  window.addEventListener('keydown', (e) => {
    if (e.key === 'Shift') keys.add(e.code);
    if (e.target instanceof HTMLInputElement || e.ctrlKey || e.metaKey || e.altKey) return;
    if (moves[e.code]) {
      stop();
      keys.add(e.code);
      e.preventDefault();
    } else if (e.code === 'KeyR') reset();
    else if (e.code === 'KeyH') $('panel').hidden = !$('panel').hidden;
    else if (e.code === 'Digit1') play('generation');
    else if (e.code === 'Digit2') play('video');
  });
  window.addEventListener('keyup', (e) => keys.delete(e.code));
  window.addEventListener('blur', () => keys.clear());
  const step = new THREE.Vector3();
  function fly(dt) {
    step.set(0, 0, 0);
    for (const code of keys) if (moves[code]) step.add(new THREE.Vector3(...moves[code]));
    if (step.lengthSq() === 0) return;
    const fast = keys.has('ShiftLeft') || keys.has('ShiftRight') ? 4 : 1;
    step.normalize().multiplyScalar(0.5 * scale * dt * fast).applyQuaternion(camera.quaternion);
    camera.position.add(step);
    controls.target.add(step);
  }
  controls.addEventListener('start', stop);

  $('play-generation').disabled = !paths.generation;
  $('play-video').disabled = !paths.video;
  $('play-generation').onclick = () => play('generation');
  $('play-video').onclick = () => play('video');
  $('reset').onclick = reset;
  $('fov').oninput = (e) => { zoom = Math.pow(2, -Number(e.target.value)); };
  window.addEventListener('resize', () => renderer.setSize(window.innerWidth, window.innerHeight));

  const sh = config.scene.sh_degree;
  let last = performance.now(), fpsFrames = 0, fpsSince = last;
  const statsText = (fps) =>
    `${mesh.numSplats.toLocaleString('en-US')} Gaussians \u00b7 SH degree ${sh}` + (fps ? ` \u00b7 ${fps} fps` : '');
  $('stats').textContent = statsText(0);
  reset();
  renderer.setAnimationLoop((now) => {
    const dt = Math.min((now - last) / 1000, 0.1);
    last = now;
    if (playing) advance(now);
    else fly(dt);
    state.playing = !!playing;
    project();
    renderer.render(scene, camera);
    state.frames++;
    fpsFrames++;
    if (now - fpsSince >= 1000) {
      $('stats').textContent = statsText(Math.round((fpsFrames * 1000) / (now - fpsSince)));
      fpsFrames = 0;
      fpsSince = now;
    }
  });
  state.ready = true;
}

main().catch((e) => state.fail(e && e.message ? e.message : String(e)));
