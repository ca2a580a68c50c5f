// Opens a viewer page in headless Chromium, waits until the scene is on screen, hides the
// overlay panel (key H) and takes a screenshot once the picture has stopped changing. Talks
// the Chrome DevTools protocol over --remote-debugging-pipe, so it needs nothing beyond node
// and a Chromium.
//
//   node shoot.mjs --browser /usr/bin/chromium --page viewer.html --out shot.png
//                  --width W --height H [--timeout SECONDS] [--steps STEPS]
//
// STEPS, separated by ';', replace the single screenshot: press:CODE (a key, by its
// KeyboardEvent.code: KeyW, Digit1, ...), hold:CODE:MS, drag:X0,Y0,X1,Y1 (left button, in
// ten moves), wheel:X,Y,DELTA, idle (until no camera path is playing), shot:FILE.
//
// Prints one JSON line: {"state": window.g3d's ready/error/frames/gaussians, "console":
// [{level, text}] (every console message, uncaught exception and browser log entry),
// "webgl": renderer string, "screenshots": how many were written}. Exits 0 when it could drive the browser,
// whatever the page showed; 1 (with a message on stderr) when it could not.
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { pathToFileURL } from 'node:url';

const args = process.argv.slice(2);
const opt = (name, fallback) => {
  const i = args.indexOf(name);
  if (i >= 0 && i + 1 < args.length) return args[i + 1];
  if (fallback === undefined) {
    console.error(`shoot.mjs: missing ${name}`);
    process.exit(1);
  }
  return fallback;
};
const browserPath = opt('--browser');
const page = resolve(opt('--page'));
const out = opt('--out');
const width = Number(opt('--width')), height = Number(opt('--height'));
const timeoutMs = Number(opt('--timeout', '120')) * 1000;

const profile = mkdtempSync(join(tmpdir(), 'g3d-chromium-'));
const browser = spawn(browserPath, [
  '--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
  '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run',
  '--no-default-browser-check', '--disable-default-apps', '--disable-extensions', '--mute-audio',
  '--hide-scrollbars', `--user-data-dir=${profile}`, `--window-size=${width},${height}`,
  '--remote-debugging-pipe', 'about:blank',
], { stdio: ['ignore', 'ignore', 'pipe', 'pipe', 'pipe'] });
let stderr = '';
browser.stderr.on('data', (d) => { stderr = (stderr + d).slice(-4000); });

function finish(code, message) {
  if (message) console.error(`shoot.mjs: ${message}${stderr ? `\nchromium said:\n${stderr}` : ''}`);
  try { browser.kill('SIGKILL'); } catch {}
  try { rmSync(profile, { recursive: true, force: true }); } catch {}
  process.exit(code);
}
browser.on('error', (e) => finish(1, `cannot start ${browserPath}: ${e.message}`));
browser.on('exit', (code) => { if (!done) finish(1, `chromium exited early (status ${code})`); });
const watchdog = setTimeout(() => finish(1, `no result within ${timeoutMs / 1000} s`), timeoutMs + 30000);
let done = false;

// the protocol: NUL-terminated JSON messages, commands on fd 3, replies and events on fd 4
const toBrowser = browser.stdio[3], fromBrowser = browser.stdio[4];
let nextId = 1, buffer = '';
const pending = new Map(), listeners = [];
fromBrowser.on('data', (chunk) => {
  buffer += chunk.toString('utf8');
  let end;
  while ((end = buffer.indexOf('\0')) >= 0) {
    const msg = JSON.parse(buffer.slice(0, end));
    buffer = buffer.slice(end + 1);
    if (msg.id && pending.has(msg.id)) {
      const { ok, fail } = pending.get(msg.id);
      pending.delete(msg.id);
      if (msg.error) fail(new Error(`${msg.error.message} (${msg.error.code})`));
      else ok(msg.result);
    } else if (msg.method) {
      for (const fn of listeners) fn(msg);
    }
  }
});
function send(method, params = {}, sessionId) {
  const id = nextId++;
  toBrowser.write(JSON.stringify({ id, method, params, sessionId }) + '\0');
  return new Promise((ok, fail) => pending.set(id, { ok, fail }));
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

const consoleLog = [];
listeners.push((m) => {
  const p = m.params;
  if (m.method === 'Runtime.consoleAPICalled')
    consoleLog.push({ level: p.type, text: p.args.map((a) => a.value ?? a.description ?? '').join(' ') });
  else if (m.method === 'Runtime.exceptionThrown')
    consoleLog.push({ level: 'exception', text: p.exceptionDetails.exception?.description ?? p.exceptionDetails.text });
  else if (m.method === 'Log.entryAdded')
    consoleLog.push({ level: p.entry.level, text: `${p.entry.source}: ${p.entry.text}` });
});

async function main() {
  const { targetId } = await send('Target.createTarget', { url: 'about:blank' });
  const { sessionId } = await send('Target.attachToTarget', { targetId, flatten: true });
  const s = (method, params) => send(method, params, sessionId);
  await s('Runtime.enable');
  await s('Log.enable');
  await s('Page.enable');
  await s('Emulation.setDeviceMetricsOverride', { width, height, deviceScaleFactor: 1, mobile: false });
  await s('Page.navigate', { url: pathToFileURL(page).href });
  const evaluate = async (expr) => (await s('Runtime.evaluate', { expression: expr, returnByValue: true })).result.value;

  const t0 = Date.now();
  let state = null;
  while (Date.now() - t0 < timeoutMs) {
    state = await evaluate('window.g3d ? {ready: g3d.ready, error: g3d.error, frames: g3d.frames, gaussians: g3d.gaussians} : null');
    if (state && (state.error || (state.ready && state.frames > 2))) break;
    await sleep(200);
  }
  const webgl = await evaluate(`(() => { const c = document.createElement('canvas').getContext('webgl2');
    const e = c && c.getExtension('WEBGL_debug_renderer_info');
    return c ? (e ? c.getParameter(e.UNMASKED_RENDERER_WEBGL) : 'webgl2') : null; })()`);
  const key = async (code, type) => {
    const k = code.startsWith('Key') ? code.slice(3).toLowerCase() : code.startsWith('Digit') ? code.slice(5) : code;
    await s('Input.dispatchKeyEvent', { type, code, key: k, windowsVirtualKeyCode: k.toUpperCase().charCodeAt(0),
      text: type === 'keyDown' && k.length === 1 ? k : undefined });
  };
  // Spark sorts in a worker and may redraw a few times: wait for two identical pictures
  const shoot = async (file) => {
    let shot = null;
    for (let k = 0; k < 20 && Date.now() - t0 < timeoutMs; k++) {
      const next = (await s('Page.captureScreenshot', { format: 'png' })).data;
      if (next === shot) break;
      shot = next;
      await sleep(400);
    }
    if (shot) writeFileSync(file, Buffer.from(shot, 'base64'));
    return !!shot;
  };
  let shots = 0;
  if (state && state.ready) {
    await key('KeyH', 'keyDown');
    await key('KeyH', 'keyUp');
    for (const step of opt('--steps', `shot:${out}`).split(';')) {
      const [what, a, b] = step.split(':');
      if (what === 'press') {
        await key(a, 'keyDown');
        await key(a, 'keyUp');
      } else if (what === 'hold') {
        await key(a, 'keyDown');
        await sleep(Number(b));
        await key(a, 'keyUp');
      } else if (what === 'drag') {
        const [x0, y0, x1, y1] = a.split(',').map(Number);
        const mouse = (type, x, y) => s('Input.dispatchMouseEvent', { type, x, y, button: 'left', buttons: type === 'mouseReleased' ? 0 : 1, clickCount: 1 });
        await mouse('mousePressed', x0, y0);
        for (let k = 1; k <= 10; k++) {
          await mouse('mouseMoved', x0 + ((x1 - x0) * k) / 10, y0 + ((y1 - y0) * k) / 10);
          await sleep(30);
        }
        await mouse('mouseReleased', x1, y1);
      } else if (what === 'wheel') {
        const [x, y, delta] = a.split(',').map(Number);
        await s('Input.dispatchMouseEvent', { type: 'mouseWheel', x, y, deltaX: 0, deltaY: delta });
      } else if (what === 'idle') {
        while (Date.now() - t0 < timeoutMs && (await evaluate('g3d.playing'))) await sleep(200);
      } else if (what === 'shot') {
        shots += await shoot(a);
      } else {
        throw new Error(`unknown step '${step}'`);
      }
    }
  } else {
    shots += await shoot(out);  // what the page shows instead: the error, or nothing
  }
  state = await evaluate('window.g3d ? {ready: g3d.ready, error: g3d.error, frames: g3d.frames, gaussians: g3d.gaussians} : null');
  console.log(JSON.stringify({ state, console: consoleLog, webgl, screenshots: shots }));
  done = true;
  await send('Browser.close').catch(() => {});
  clearTimeout(watchdog);
  finish(0);
}

main().catch((e) => finish(1, e.message));
