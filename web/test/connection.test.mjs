// connection.js against a scripted fake WebSocket: handshake, auth, replies, reconnection.
import { test, mock } from 'node:test';
import assert from 'node:assert/strict';
import { Connection, ServerError, socketUrl } from '../js/connection.js';
import { Type, encode, decode, Capability, ErrorCode } from '../js/protocol.js';

// Browsers and Node 19+ have CustomEvent; Debian 12's Node 18 does not (connection.js only
// dispatches it).
globalThis.CustomEvent ??= class CustomEvent extends Event {
  constructor(type, init = {}) {
    super(type, init);
    this.detail = init.detail ?? null;
  }
};

class FakeSocket {
  static all = [];
  constructor(url) {
    this.url = url;
    this.readyState = 0;
    this.sent = [];
    FakeSocket.all.push(this);
  }
  send(b) { this.sent.push(decode(b, 64 * 1024)); }
  close(code = 1000) { if (this.readyState === 3) return; this.readyState = 3; this.onclose?.({ code, reason: '' }); }
  open() { this.readyState = 1; this.onopen?.(); }
  receive(type, body, request = 0) { this.onmessage?.({ data: encode(type, body, request) }); }
}

class FakeStorage {
  constructor() { this.map = new Map(); }
  getItem(k) { return this.map.get(k) ?? null; }
  setItem(k, v) { this.map.set(k, v); }
  removeItem(k) { this.map.delete(k); }
}

// Fake setTimeout: Node 20.4+ takes { apis }, Node 18 (Debian 12's) a list.
function enableFakeTimeouts() {
  try {
    mock.timers.enable({ apis: ['setTimeout'] });
  } catch (e) {
    if (e.code !== 'ERR_INVALID_ARG_TYPE') throw e;
    mock.timers.enable(['setTimeout']);
  }
}

const serverHello = (capabilities) => ({ versionMin: 1, versionMax: 1, capabilities, codecs: [0, 3, 4], software: 'test' });

function connect(storage = new FakeStorage()) {
  FakeSocket.all = [];
  const c = new Connection('ws://x/ws', { WebSocketImpl: FakeSocket, storage });
  const states = [];
  c.addEventListener('state', (e) => states.push(e.detail.state));
  c.connect();
  const ws = FakeSocket.all[0];
  ws.open();
  return { c, ws, states, storage };
}

test('sends the web client\'s Hello first and is ready when no auth is needed', () => {
  const { c, ws, states } = connect();
  assert.equal(ws.sent[0].name, 'Hello');
  assert.deepEqual(ws.sent[0].body, { versionMin: 1, versionMax: 1, capabilities: 0, codecs: [3, 4, 0], software: 'brickcast-web' });
  ws.receive(Type.Hello, serverHello(Capability.CpuRenderer), ws.sent[0].request);
  assert.equal(c.state, 'ready');
  assert.deepEqual(states, ['connecting', 'ready']);
  assert.ok(c.hasCodec(4) && !c.hasCodec(1));
  assert.ok(c.can(Capability.CpuRenderer) && !c.can(Capability.GpuRenderer));
  assert.ok(!c.can(Capability.FrameBudget), 'a server without bit 4 does not take SetFrameBudget');
});

test('the frame-budget capability is Hello bit 4', () => {
  const { c, ws } = connect();
  assert.ok(!c.can(Capability.FrameBudget), 'nothing is known before the server\'s Hello');
  ws.receive(Type.Hello, serverHello(Capability.CpuRenderer | (1 << 4)), ws.sent[0].request);
  assert.ok(c.can(Capability.FrameBudget) && c.can(Capability.CpuRenderer));
});

test('request ids increase and replies resolve their request; Errors reject it', async () => {
  const { c, ws } = connect();
  ws.receive(Type.Hello, serverHello(0), 1);
  const list = c.request(Type.ListVolumes, {}, Type.VolumeList);
  const open = c.request(Type.OpenVolume, { name: 'nope' }, Type.VolumeOpened);
  const [a, b] = ws.sent.slice(1);
  assert.ok(b.request > a.request && a.request > ws.sent[0].request);
  ws.receive(Type.VolumeList, { volumes: [] }, a.request);
  ws.receive(Type.Error, { code: ErrorCode.UnknownVolume, fatal: false, offendingType: Type.OpenVolume, message: 'no volume named \'nope\'' }, b.request);
  assert.deepEqual(await list, { volumes: [] });
  await assert.rejects(open, (e) => e instanceof ServerError && e.codeName === 'UnknownVolume' && /OpenVolume/.test(e.message));
  assert.equal(c.state, 'ready', 'a non-fatal Error leaves the session as it was');
});

test('auth: asks for a token, sends Auth, keeps it only when asked; AuthFailed asks again', () => {
  const { c, ws, storage } = connect();
  const asks = [];
  c.addEventListener('auth', (e) => asks.push(e.detail));
  ws.receive(Type.Hello, serverHello(Capability.AuthRequired), 1);
  assert.equal(c.state, 'auth');
  assert.deepEqual(asks, [{ failed: false, message: 'this server requires an access token' }]);
  c.submitToken('wrong', true);
  assert.equal(ws.sent.at(-1).name, 'Auth');
  assert.equal(ws.sent.at(-1).body.token, 'wrong');
  assert.equal(storage.getItem('brickcast.token'), 'wrong');
  ws.receive(Type.Error, { code: ErrorCode.AuthFailed, fatal: true, offendingType: Type.Auth, message: 'wrong token' }, ws.sent.at(-1).request);
  ws.close(1000);
  assert.equal(c.state, 'auth', 'no reconnect loop with a rejected token');
  assert.equal(asks.at(-1).failed, true);
  assert.equal(storage.getItem('brickcast.token'), null, 'a rejected token is forgotten');
  c.submitToken('right', false);
  const ws2 = FakeSocket.all.at(-1);
  assert.notEqual(ws2, ws);
  ws2.open();
  ws2.receive(Type.Hello, serverHello(Capability.AuthRequired), 1);
  assert.equal(ws2.sent.at(-1).body.token, 'right');
  ws2.receive(Type.AuthOk, {}, ws2.sent.at(-1).request);
  assert.equal(c.state, 'ready');
  assert.equal(storage.getItem('brickcast.token'), null);
});

test('a lost connection reconnects with growing backoff; Reconnect skips the wait', () => {
  enableFakeTimeouts();
  try {
    const { c, ws, states } = connect();
    ws.receive(Type.Hello, serverHello(0), 1);
    const delays = [];
    c.addEventListener('state', (e) => { if (e.detail.state === 'disconnected') delays.push(e.detail.retryInMs); });
    ws.close(1006);
    assert.equal(c.state, 'disconnected');
    mock.timers.tick(delays[0]);
    assert.equal(FakeSocket.all.length, 2);
    FakeSocket.all[1].close(1006);
    assert.ok(delays[1] > delays[0] * 0.9, `backoff grows: ${delays}`);
    c.reconnectNow();
    assert.equal(FakeSocket.all.length, 3);
    assert.equal(c.state, 'connecting');
    assert.ok(states.includes('disconnected'));
  } finally {
    mock.timers.reset();
  }
});

test('an idle-timeout Bye waits for the Reconnect button', () => {
  enableFakeTimeouts();
  try {
    const { c, ws } = connect();
    ws.receive(Type.Hello, serverHello(0), 1);
    let reason = '';
    c.addEventListener('state', (e) => { reason = e.detail.reason; });
    ws.receive(Type.Bye, { reason: 2 }, 0);
    ws.close(1000);
    mock.timers.tick(60000);
    assert.equal(FakeSocket.all.length, 1);
    assert.equal(c.state, 'disconnected');
    assert.equal(reason, 'idle timeout');
  } finally {
    mock.timers.reset();
  }
});

test('a framing error from the server is answered with Error and a close', () => {
  const { c, ws } = connect();
  ws.receive(Type.Hello, serverHello(0), 1);
  const errors = [];
  c.addEventListener('error', (e) => errors.push(e.detail));
  const bad = new Uint8Array(encode(Type.AuthOk, {}, 0));
  bad[0] = 0x41;
  ws.onmessage({ data: bad.buffer });
  assert.equal(ws.sent.at(-1).name, 'Error');
  assert.equal(ws.sent.at(-1).body.code, ErrorCode.BadMagic);
  assert.equal(ws.readyState, 3);
  assert.match(errors[0].message, /malformed message from the server: bad magic/);
  c.close();
});

test('the socket is /ws beside the page, wss under https', () => {
  assert.equal(socketUrl('http://host:8080/'), 'ws://host:8080/ws');
  assert.equal(socketUrl('https://host/index.html'), 'wss://host/ws');
});
