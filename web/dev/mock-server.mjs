// A stand-in for brickcastd, Node built-ins only, for trying the page in a browser without the
// C++ server: it serves web/ and /presets.json (from configs/tf/) and answers the protocol on
// /ws with one synthetic volume and PNG or raw frames that show the camera's view direction.
// It is no reference for the server's behaviour beyond what PROTOCOL.md says.
//
//   node web/dev/mock-server.mjs [--port 8123] [--token SECRET] [--inject script.js]
//
// --inject adds a script to index.html (browser smoke tests drive window.brickcast with it).

import http from 'node:http';
import crypto from 'node:crypto';
import zlib from 'node:zlib';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { Type, Codec, ErrorCode, encode, decode } from '../js/protocol.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const webRoot = path.resolve(here, '..');
const tfDir = path.resolve(webRoot, '..', 'configs', 'tf');
const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) => (a.startsWith('--') ? [...acc, [a.slice(2), all[i + 1]]] : acc), []));
const port = Number(args.port ?? 8123);
const token = args.token ?? null;
const inject = args.inject ? fs.readFileSync(args.inject, 'utf8') : null;

const VOLUME = {
  name: 'phantom', dims: [64, 64, 32], spacingMm: [1, 1, 2], voxelType: 0, levels: 2,
  valueMin: 0, valueMax: 255, storedBytes: 64 * 64 * 32 + 4096,
};
const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.svg': 'image/svg+xml', '.json': 'application/json' };

function presets() {
  return fs.readdirSync(tfDir).filter((f) => f.endsWith('.json')).sort()
    .map((f) => JSON.parse(fs.readFileSync(path.join(tfDir, f), 'utf8')));
}

const server = http.createServer((req, res) => {
  const url = new URL(req.url, 'http://x');
  if (url.pathname === '/presets.json') return send(res, 200, '.json', JSON.stringify(presets()));
  const rel = url.pathname === '/' ? 'index.html' : url.pathname.slice(1);
  // Exact file paths under web/ only, one folder deep at most, as brickcastd serves them.
  if (!/^([A-Za-z0-9_-]+\/)?[A-Za-z0-9_.-]+\.(html|js|css|svg|json)$/.test(rel) || rel.includes('..')) return send(res, 404, '.html', 'not found');
  const file = path.join(webRoot, rel);
  if (!fs.existsSync(file)) return send(res, 404, '.html', 'not found');
  let body = fs.readFileSync(file, 'utf8');
  if (rel === 'index.html' && inject) body = body.replace('</body>', `<script type="module">${inject}</script></body>`);
  return send(res, 200, path.extname(rel), body);
});

function send(res, status, ext, body) {
  res.writeHead(status, { 'content-type': `${TYPES[ext]}; charset=utf-8`, 'cache-control': 'no-store' });
  res.end(body);
}

// ---- WebSocket (RFC 6455): binary messages, no extensions ----

server.on('upgrade', (req, socket) => {
  if (new URL(req.url, 'http://x').pathname !== '/ws') return socket.destroy();
  const accept = crypto.createHash('sha1').update(req.headers['sec-websocket-key'] + '258EAFA5-E914-47DA-95CA-C5AB0DC85B11').digest('base64');
  socket.write(`HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: ${accept}\r\n\r\n`);
  socket.setNoDelay(true);
  const session = new Session((buf) => wsSend(socket, 2, buf), () => wsClose(socket));
  let pending = Buffer.alloc(0);
  let fragments = [];
  socket.on('data', (chunk) => {
    pending = Buffer.concat([pending, chunk]);
    for (;;) {
      const f = parseFrame(pending);
      if (!f) break;
      pending = pending.subarray(f.size);
      if (f.opcode === 8) { wsClose(socket); return; }
      if (f.opcode === 9) { wsSend(socket, 10, f.payload); continue; }
      if (f.opcode === 0 || f.opcode === 2 || f.opcode === 1) {
        fragments.push(f.payload);
        if (!f.fin) continue;
        const msg = Buffer.concat(fragments);
        fragments = [];
        session.receive(msg.buffer.slice(msg.byteOffset, msg.byteOffset + msg.length));
      }
    }
  });
  socket.on('close', () => session.stop());
  socket.on('error', () => session.stop());
});

function parseFrame(b) {
  if (b.length < 2) return null;
  const fin = (b[0] & 0x80) !== 0, opcode = b[0] & 0x0f, masked = (b[1] & 0x80) !== 0;
  let len = b[1] & 0x7f, off = 2;
  if (len === 126) { if (b.length < 4) return null; len = b.readUInt16BE(2); off = 4; }
  else if (len === 127) { if (b.length < 10) return null; len = Number(b.readBigUInt64BE(2)); off = 10; }
  const maskOff = off;
  if (masked) off += 4;
  if (b.length < off + len) return null;
  const payload = Buffer.from(b.subarray(off, off + len));
  if (masked) for (let i = 0; i < len; ++i) payload[i] ^= b[maskOff + (i & 3)];
  return { fin, opcode, payload, size: off + len };
}

function wsSend(socket, opcode, data) {
  if (socket.destroyed) return;
  const payload = Buffer.from(data);
  const n = payload.length;
  const head = n < 126 ? Buffer.from([0x80 | opcode, n])
    : n < 65536 ? Buffer.from([0x80 | opcode, 126, n >> 8, n & 0xff])
      : Buffer.concat([Buffer.from([0x80 | opcode, 127]), (() => { const x = Buffer.alloc(8); x.writeBigUInt64BE(BigInt(n)); return x; })()]);
  socket.write(Buffer.concat([head, payload]));
}

function wsClose(socket) {
  if (socket.destroyed) return;
  wsSend(socket, 8, Buffer.from([0x03, 0xe8]));
  socket.end();
}

// ---- the protocol ----

class Session {
  constructor(out, close) {
    Object.assign(this, { out, close });
    this.helloDone = false;
    this.authed = !token;
    this.volume = null;
    this.camera = null;
    this.options = null;
    this.continuous = false;
    this.frameId = 0;
    this.restTimer = null;
    this.renders = 0;
  }

  stop() { clearTimeout(this.restTimer); }

  reply(type, body, request) { this.out(encode(type, body, request)); }

  error(code, fatal, offendingType, message, request) {
    this.reply(Type.Error, { code, fatal, offendingType, message }, request);
    if (fatal) this.close();
  }

  receive(buffer) {
    let m;
    try {
      m = decode(buffer, 64 * 1024);
    } catch (e) {
      return this.error(ErrorCode[e.code] ?? ErrorCode.BadPayload, ['BadMagic', 'UnsupportedVersion', 'TooLarge'].includes(e.code), 0, e.message, 0);
    }
    const { type, request: id, body } = m;
    if (type === Type.Hello) {
      this.helloDone = true;
      return this.reply(Type.Hello, { versionMin: 1, versionMax: 1, capabilities: (token ? 1 : 0) | 2 | 4 | 8, codecs: [0, 4], software: 'mock-brickcastd' }, id);
    }
    if (type === Type.Auth) {
      if (body.token !== token) return this.error(ErrorCode.AuthFailed, true, type, 'wrong token', id);
      this.authed = true;
      return this.reply(Type.AuthOk, {}, id);
    }
    if (!this.authed) return this.error(ErrorCode.NotAuthenticated, true, type, 'authenticate first', id);
    switch (type) {
      case Type.ListVolumes: return this.reply(Type.VolumeList, { volumes: [VOLUME] }, id);
      case Type.OpenVolume:
        if (body.name !== VOLUME.name) return this.error(ErrorCode.UnknownVolume, false, type, `no volume named '${body.name}' in the catalog`, id);
        this.volume = VOLUME;
        return this.reply(Type.VolumeOpened, VOLUME, id);
      case Type.RequestHistogram: {
        if (!this.volume) return this.error(ErrorCode.NoVolume, false, type, 'no volume is open', id);
        const counts = new Float64Array(256).map((_, i) => (i < 8 ? 90000 : Math.round(4000 * Math.exp(-((i - 120) ** 2) / 800)) + 10));
        return this.reply(Type.Histogram, { valueMin: 0, valueMax: 255, counts }, id);
      }
      case Type.SetCamera: this.camera = body; this.requestId = id; return this.changed(true);
      case Type.SetRenderOptions: this.options = body; return this.changed(false);
      case Type.SetTransferFunction: this.tf = body; return this.changed(false);
      case Type.RequestFrame:
        if (!this.volume) return this.error(ErrorCode.NoVolume, false, type, 'no volume is open', id);
        this.continuous = body.mode === 1 ? true : body.mode === 2 ? false : this.continuous;
        if (body.mode !== 2) this.render(this.quality() !== 2);
        return undefined;
      case Type.RequestStats:
        return this.reply(Type.Stats, { counters: [{ name: 'frames', value: this.frameId }, { name: 'bricks resident', value: 42 }, { name: 'brick cache hits', value: 0.93 }] }, id);
      case Type.Bye: return this.close();
      default: return this.error(ErrorCode.UnknownType, false, type, 'not handled by the mock', id);
    }
  }

  quality() { return this.options?.quality ?? 0; }

  changed(cameraMoved) {
    if (!this.continuous || !this.volume) return;
    const q = this.quality();
    clearTimeout(this.restTimer);
    if (q === 1) return this.render(true);
    this.render(q === 2 ? false : !cameraMoved);
    // Adaptive: one refined frame once the camera rests.
    if (q === 0 && cameraMoved) this.restTimer = setTimeout(() => this.render(true), 150);
  }

  render(refined) {
    if (!this.camera) return;
    const o = this.options ?? { width: 256, height: 256, codec: 0, refinedCodec: 0 };
    const codec = refined && o.refinedCodec ? o.refinedCodec - 1 : o.codec;
    const { width, height } = o;
    const rgba = Buffer.alloc(width * height * 4);
    const d = this.camera.target.map((t, i) => t - this.camera.eye[i]);
    const n = Math.hypot(...d);
    const c = d.map((v) => Math.round(127 + 127 * v / n));
    for (let y = 0; y < height; ++y) {
      for (let x = 0; x < width; ++x) {
        const inside = Math.hypot(x - width / 2, y - height / 2) < Math.min(width, height) * 0.35;
        const k = 4 * (y * width + x);
        rgba[k] = inside ? c[0] : 0; rgba[k + 1] = inside ? c[1] : 0; rgba[k + 2] = inside ? c[2] : 0; rgba[k + 3] = inside ? 255 : 0;
      }
    }
    let image;
    if (codec === Codec.Png) image = png(rgba, width, height);
    else if (codec === Codec.Raw) image = rgba;
    else return this.error(ErrorCode.OutOfRange, false, Type.SetRenderOptions, `codec ${codec}: the mock encodes raw and PNG only`, 0);
    this.frameId += 1;
    this.reply(Type.Frame, {
      frameId: this.frameId, cameraId: this.camera.cameraId, width, height, codec, level: refined ? 0 : 1,
      refined, keyframe: false, queueMs: 0.1, renderMs: 3.5, encodeMs: 1.25, samples: width * height * 64,
      bricksDrawn: 12, bricksSkipped: 4, bytesUploaded: 0, occlusionUsed: false, image: new Uint8Array(image),
    }, 0);
  }
}

// ---- PNG: 8-bit RGB, alpha dropped (the colour is premultiplied, i.e. over black) ----

const crcTable = new Uint32Array(256).map((_, n) => {
  let c = n;
  for (let k = 0; k < 8; ++k) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
  return c >>> 0;
});

function crc32(buf) {
  let c = 0xffffffff;
  for (const b of buf) c = crcTable[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

function chunk(type, data) {
  const len = Buffer.alloc(4);
  len.writeUInt32BE(data.length);
  const body = Buffer.concat([Buffer.from(type, 'ascii'), data]);
  const crc = Buffer.alloc(4);
  crc.writeUInt32BE(crc32(body));
  return Buffer.concat([len, body, crc]);
}

function png(rgba, width, height) {
  const raw = Buffer.alloc(height * (1 + width * 3));
  for (let y = 0; y < height; ++y) {
    const row = y * (1 + width * 3);
    for (let x = 0; x < width; ++x) rgba.copy(raw, row + 1 + x * 3, 4 * (y * width + x), 4 * (y * width + x) + 3);
  }
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(width, 0);
  ihdr.writeUInt32BE(height, 4);
  ihdr.set([8, 2, 0, 0, 0], 8);
  return Buffer.concat([
    Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]),
    chunk('IHDR', ihdr), chunk('IDAT', zlib.deflateSync(raw, { level: 1 })), chunk('IEND', Buffer.alloc(0)),
  ]);
}

server.listen(port, '127.0.0.1', () => process.stdout.write(`mock brickcastd on http://127.0.0.1:${port}/\n`));
