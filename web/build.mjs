// Builds the viewer template: one HTML file holding the whole viewer (three.js, Spark and
// src/*.js, bundled by esbuild), into which gen3d later writes a scene.
//
//   node web/build.mjs --modules DIR/node_modules --out FILE
//
// DIR/node_modules is what `npm ci` installed from web/package-lock.json. The bundle and
// Spark's WebAssembly travel gzip-compressed in a binary block (see src/boot.js for the
// encoding) because the page must stay within 1 MB of the scene: as base64 text they would
// take 3.3 MB. Spark carries its WebAssembly as a base64 literal; the build takes it out as
// bytes and the page hands it back to Spark through globalThis.__g3dSparkWasm.
//
// The output keeps two placeholders, each exactly once, for gen3d to fill:
//   @@G3D_CONFIG@@  the JSON description   @@G3D_SCENE@@  the .spz binary block
import { readFileSync, writeFileSync, renameSync, unlinkSync } from 'node:fs';
import { createRequire } from 'node:module';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { gzipSync, constants as zc } from 'node:zlib';

const here = dirname(fileURLToPath(import.meta.url));

function fail(message) {
  console.error(`web/build.mjs: ${message}`);
  process.exit(1);
}

const args = process.argv.slice(2);
const opt = (name) => {
  const i = args.indexOf(name);
  if (i < 0 || i + 1 >= args.length) fail(`usage: node build.mjs --modules DIR/node_modules --out FILE (missing ${name})`);
  return args[i + 1];
};
const modules = resolve(opt('--modules'));
const outPath = opt('--out');
const esbuild = createRequire(join(modules, '..', 'package.json'))('esbuild');

// The binary-block encoding of src/boot.js (and of gen3d's src/io/viewer.c).
function encodeBlock(bytes) {
  const out = Buffer.alloc(bytes.length * 2);
  let n = 0;
  for (let i = 0; i < bytes.length; i++) {
    const b = bytes[i];
    const next = bytes[i + 1];
    if (b === 0x00 || b === 0x0d || b === 0x3d || (b === 0x3c && (next === 0x2f || next === 0x21))) {
      out[n++] = 0x3d;
      out[n++] = (b + 64) & 0xff;
    } else {
      out[n++] = b;
    }
  }
  return out.subarray(0, n);
}

let wasm = null;
const sparkWasm = {
  name: 'spark-wasm',
  setup(build) {
    build.onLoad({ filter: /[\\/]@sparkjsdev[\\/]spark[\\/]dist[\\/]spark\.module\.js$/ }, (args) => {
      const src = readFileSync(args.path, 'utf8');
      const literal = /const WASM = decode64\("([A-Za-z0-9+/=]+)"\)\.buffer;/g;
      const found = [...src.matchAll(literal)];
      if (found.length !== 1)
        fail(`${args.path}: expected one inlined WebAssembly module, found ${found.length} (Spark changed; update sparkWasm)`);
      wasm = Buffer.from(found[0][1], 'base64');
      if (wasm.subarray(0, 4).toString('latin1') !== '\0asm') fail(`${args.path}: the inlined module is not WebAssembly`);
      return { contents: src.replace(literal, "const WASM = globalThis.__g3dSparkWasm;"), loader: 'js' };
    });
  },
};

async function bundle(entry, plugins) {
  const result = await esbuild.build({
    entryPoints: [join(here, 'src', entry)],
    bundle: true,
    format: 'iife',
    target: 'es2020',
    minify: true,
    legalComments: 'none',
    charset: 'ascii',
    nodePaths: [modules],
    plugins,
    write: false,
    logLevel: 'warning',
  });
  return result.outputFiles[0].text;
}

const viewerJs = await bundle('main.js', [sparkWasm]);
const bootJs = await bundle('boot.js', []);
if (!wasm) fail("Spark's WebAssembly module was not found in the bundle");
if (/<\/script|<!--/i.test(bootJs)) fail('the boot script contains "</script" or "<!--"');

const jsBytes = Buffer.from(viewerJs, 'utf8');
const header = Buffer.alloc(4);
header.writeUInt32LE(jsBytes.length, 0);
const packed = gzipSync(Buffer.concat([header, jsBytes, wasm]), { level: zc.Z_BEST_COMPRESSION });

const version = (name) => JSON.parse(readFileSync(join(modules, name, 'package.json'), 'utf8')).version;
const licence = (name) =>
  `${name} ${version(name)}:\n${readFileSync(join(modules, name, 'LICENSE'), 'utf8').replace(/\u00a9/g, '(c)').trim()}`;
const notices = ['three', '@sparkjsdev/spark', 'fflate'].map(licence).join('\n\n');
if (/[^\x09\x0a\x20-\x7e]|-->/.test(notices)) fail('a licence text holds characters that cannot go into the page comment');

let template = readFileSync(join(here, 'src', 'template.html'), 'utf8');
if (/[^\x09\x0a\x20-\x7e]/.test(template)) fail('src/template.html must be plain ASCII (use HTML entities)');
template = template
  .replace('<!--G3D_LICENSES-->', () => `<!-- The gen3d scene viewer. It contains:\n\n${notices}\n-->`)
  .replace('/*G3D_BOOT*/', () => bootJs.trim());
const [before, after] = template.split('/*G3D_VIEWER*/');
if (after === undefined) fail('src/template.html lacks /*G3D_VIEWER*/');
const page = Buffer.concat([Buffer.from(before, 'latin1'), encodeBlock(packed), Buffer.from(after, 'latin1')]);

for (const mark of ['@@G3D_CONFIG@@', '@@G3D_SCENE@@']) {
  const first = page.indexOf(mark);
  if (first < 0 || page.indexOf(mark, first + 1) >= 0) fail(`the page must hold ${mark} exactly once`);
}

const tmp = `${outPath}.tmp-${process.pid}`;
try {
  writeFileSync(tmp, page);
  renameSync(tmp, outPath);
} catch (e) {
  try { unlinkSync(tmp); } catch {}
  fail(`cannot write ${outPath}: ${e.message}`);
}
console.log(`viewer template: ${outPath} (${page.length} bytes; viewer ${jsBytes.length} + WebAssembly ${wasm.length} bytes, ${packed.length} compressed)`);
