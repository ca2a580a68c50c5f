// The page's first script: error reporting, the decoder for the binary blocks the page
// carries, and the start of the viewer, which travels gzip-compressed in #g3d-viewer.
//
// Binary blocks are <script type="application/octet-stream"> elements whose bytes are
// written into the page as they are (the page is windows-1252, which maps every byte to one
// character), except that 0x00, 0x0D, '=' and a '<' before '/' or '!' -- the bytes an HTML
// parser would alter or end the element at -- are written as '=' followed by the byte + 64.
// That costs about 1.2 % where base64 would cost 33 %.

// windows-1252 characters of the bytes 0x80..0x9F that are not their own code point
const CP1252 = new Map([
  [0x20ac, 0x80], [0x201a, 0x82], [0x192, 0x83], [0x201e, 0x84], [0x2026, 0x85], [0x2020, 0x86],
  [0x2021, 0x87], [0x2c6, 0x88], [0x2030, 0x89], [0x160, 0x8a], [0x2039, 0x8b], [0x152, 0x8c],
  [0x17d, 0x8e], [0x2018, 0x91], [0x2019, 0x92], [0x201c, 0x93], [0x201d, 0x94], [0x2022, 0x95],
  [0x2013, 0x96], [0x2014, 0x97], [0x2dc, 0x98], [0x2122, 0x99], [0x161, 0x9a], [0x203a, 0x9b],
  [0x153, 0x9c], [0x17e, 0x9e], [0x178, 0x9f],
]);

const state = {
  ready: false,   // the scene is loaded and being drawn
  error: null,    // the message shown instead of the scene
  frames: 0,      // frames drawn so far
  playing: false, // a camera path is playing
  gaussians: 0,
  fail(message) {
    if (state.error) return;
    state.error = message;
    const box = document.getElementById('error');
    box.textContent = message;
    box.hidden = false;
    document.getElementById('stats').textContent = 'no scene';
  },
  // The bytes of binary block `id`; `what` names it in errors.
  readBinary(id, what) {
    const el = document.getElementById(id);
    const s = el ? el.textContent : '';
    if (!s) throw new Error(`This page holds no ${what}.`);
    const out = new Uint8Array(s.length);
    let n = 0, escaped = false;
    for (let i = 0; i < s.length; i++) {
      let c = s.charCodeAt(i);
      if (c > 0xff) {
        c = CP1252.get(c);
        if (c === undefined) throw new Error(`The ${what} in this page is damaged (a character outside windows-1252; was the page saved in another encoding?).`);
      }
      if (escaped) {
        out[n++] = (c - 64) & 0xff;
        escaped = false;
      } else if (c === 0x3d) {
        escaped = true;
      } else {
        out[n++] = c;
      }
    }
    if (escaped) throw new Error(`The ${what} in this page is damaged (it ends inside an escape).`);
    return out.subarray(0, n);
  },
  // gunzip through the browser's own decoder; rejects on any corruption (CRC, length).
  async gunzip(bytes, what) {
    try {
      const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
      return new Uint8Array(await new Response(stream).arrayBuffer());
    } catch (e) {
      throw new Error(`The ${what} in this page is damaged (its compressed data is corrupt).`);
    }
  },
};
window.g3d = state;
window.addEventListener('error', (e) => state.fail(`The viewer stopped: ${e.message}`));
window.addEventListener('unhandledrejection', (e) =>
  state.fail(`The viewer stopped: ${e.reason && e.reason.message ? e.reason.message : e.reason}`));

// #g3d-viewer: gzip of [u32 little-endian length of the script][script][Spark's WebAssembly]
async function start() {
  if (typeof DecompressionStream !== 'function')
    throw new Error('This browser is too old to show the scene (it lacks DecompressionStream).');
  const packed = await state.gunzip(state.readBinary('g3d-viewer', 'viewer program'), 'viewer program');
  const n = new DataView(packed.buffer, packed.byteOffset).getUint32(0, true);
  globalThis.__g3dSparkWasm = packed.slice(4 + n).buffer;
  const script = document.createElement('script');
  script.textContent = new TextDecoder().decode(packed.subarray(4, 4 + n));
  document.body.appendChild(script);
}

start().catch((e) => state.fail(e && e.message ? e.message : String(e)));
