// What gen3d writes into the page: #g3d-config, a JSON description (scene figures, the
// input camera, the camera paths), and #g3d-scene, the scene as a .spz (version 2) binary
// block. Everything here throws an Error with a sentence a user can read.

export function readConfig() {
  const el = document.getElementById('g3d-config');
  const text = el ? el.textContent : '';
  if (!text || text.startsWith('@@'))
    throw new Error('This page holds no scene: it is the bare viewer template. Make a viewer with "gen3d view SCENE -o viewer.html".');
  let config;
  try {
    config = JSON.parse(text);
  } catch (e) {
    throw new Error(`The scene description in this page is damaged (${e.message}).`);
  }
  if (config === null || typeof config !== 'object' || config.version !== 1 || !config.input || !config.scene)
    throw new Error('The scene description in this page is not one this viewer reads (version 1).');
  return config;
}

// The .spz bytes (gzip), checked completely: the gzip stream (CRC and length), the header
// ("NGSP", version 2, the Gaussian count of the description) and the payload size.
export async function readScene(config) {
  const g3d = window.g3d;
  const bytes = g3d.readBinary('g3d-scene', 'scene');
  if (bytes.length < 18 || bytes[0] !== 0x1f || bytes[1] !== 0x8b)
    throw new Error('The scene in this page is damaged (it is not gzip-compressed .spz data).');
  const raw = await g3d.gunzip(bytes, 'scene');
  const view = new DataView(raw.buffer, raw.byteOffset, raw.byteLength);
  if (raw.length < 16 || view.getUint32(0, true) !== 0x5053474e)
    throw new Error('The scene in this page is damaged (no .spz header).');
  const version = view.getUint32(4, true), count = view.getUint32(8, true), degree = raw[12];
  if (version !== 2) throw new Error(`The scene in this page is .spz version ${version}; this viewer reads version 2.`);
  if (count !== config.scene.gaussians)
    throw new Error(`The scene in this page is damaged (${count} Gaussians where the description says ${config.scene.gaussians}).`);
  const perGaussian = 9 + 1 + 3 + 3 + 3 + 3 * ((degree + 1) * (degree + 1) - 1);
  if (degree > 3 || raw.length !== 16 + count * perGaussian)
    throw new Error('The scene in this page is damaged (its data does not match its header).');
  return bytes;
}
