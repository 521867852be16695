// One WebSocket session with brickcastd: Hello, Auth, request ids, replies matched to
// requests, and reconnection with backoff. Each protocol message is one binary WebSocket
// message both ways. Nothing here touches the DOM; the page listens to its events.

import {
  Type, Capability, ErrorCode, ProtocolError, encode, decode, errorName, typeName,
} from './protocol.js';

const CLIENT_HELLO = Object.freeze({ versionMin: 1, versionMax: 1, capabilities: 0, codecs: [3, 4, 0], software: 'brickcast-web' });
const TOKEN_KEY = 'brickcast.token';
const BACKOFF_FIRST_MS = 500;
const BACKOFF_MAX_MS = 15000;
// Framing errors leave no way to find the next message: answer Error and close (PROTOCOL.md).
const FRAMING_ERRORS = new Set(['BadMagic', 'UnsupportedVersion', 'TooLarge']);

/** An Error message from the server, as a JavaScript error (code, codeName, fatal, offendingType, request: 0 when unasked). */
export class ServerError extends Error {
  constructor(body, request = 0) {
    const what = body.offendingType ? ` (${typeName(body.offendingType)})` : '';
    super(`${errorName(body.code)}${what}: ${body.message || 'no message'}`);
    this.name = 'ServerError';
    this.code = body.code;
    this.codeName = errorName(body.code);
    this.fatal = body.fatal;
    this.offendingType = body.offendingType;
    this.serverMessage = body.message;
    this.request = request;
  }
}

/** A request that can have no reply because the connection closed (the state event says so already). */
export class DisconnectedError extends Error {
  constructor(why) {
    super(`not answered: ${why}`);
    this.name = 'DisconnectedError';
  }
}

/** The WebSocket URL beside a page at `pageUrl`: ws(s)://host:port/ws for a page at /. */
export function socketUrl(pageUrl) {
  const u = new URL('ws', pageUrl);
  u.protocol = u.protocol === 'https:' ? 'wss:' : 'ws:';
  return u.href;
}

/**
 * Events (CustomEvent, payload in `detail`):
 *  state    {state: 'connecting'|'auth'|'ready'|'disconnected', reason, retryInMs}
 *  message  a decoded message {type, name, request, body}, every one after the handshake
 *  error    a ServerError or ProtocolError worth showing (the page decides how)
 *  auth     {failed, message}: the server wants a token; answer with submitToken()
 */
export class Connection extends EventTarget {
  /** A connection to `url`; `storage` keeps a token for the tab when asked (sessionStorage). */
  constructor(url, { WebSocketImpl = globalThis.WebSocket, storage = globalThis.sessionStorage } = {}) {
    super();
    this.url = url;
    this.WebSocketImpl = WebSocketImpl;
    this.storage = storage;
    this.state = 'disconnected';
    this.serverHello = null;
    this.ws = null;
    this.nextRequest = 1;
    this.pending = new Map();
    this.attempt = 0;
    this.retryTimer = null;
    this.token = null;
    this.waitingForToken = false;
    this.autoReconnect = true;
  }

  /** Opens the socket (closing any current one) and starts the handshake. */
  connect() {
    this.cancelRetry();
    this.dropSocket();
    this.autoReconnect = true;
    this.serverHello = null;
    this.setState('connecting');
    let ws;
    try {
      ws = new this.WebSocketImpl(this.url);
    } catch (e) {
      this.emit('error', e);
      this.onClosed(null, `cannot open ${this.url}`);
      return;
    }
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => this.sendRaw(encode(Type.Hello, CLIENT_HELLO, this.takeRequestId()));
    ws.onmessage = (e) => this.onData(e.data);
    ws.onclose = (e) => this.onClosed(ws, closeReason(e));
    this.ws = ws;
  }

  /** Reconnects at once, skipping any backoff wait (the Reconnect button). */
  reconnectNow() {
    this.attempt = 0;
    this.connect();
  }

  /** Says Bye and closes; no reconnection follows. */
  close() {
    this.autoReconnect = false;
    this.cancelRetry();
    if (this.ws && this.ws.readyState === 1) this.sendRaw(encode(Type.Bye, { reason: 0 }, 0));
    this.dropSocket();
    this.setState('disconnected', 'closed');
  }

  /** The server's capability bit `bit` from its Hello (false before one arrives). */
  can(bit) {
    return !!this.serverHello && (this.serverHello.capabilities & bit) !== 0;
  }

  /** True when the server's Hello lists codec `c`. */
  hasCodec(c) {
    return !!this.serverHello && this.serverHello.codecs.includes(c);
  }

  /** Sends one message when ready; returns its request id, or 0 when nothing was sent. Throws ProtocolError on a bad body. */
  send(type, body = {}) {
    if (this.state !== 'ready') return 0;
    const request = this.takeRequestId();
    this.sendRaw(encode(type, body, request));
    return request;
  }

  /** Sends a request and resolves with the body of the reply of type `replyType` carrying its id; rejects with ServerError or on disconnect. */
  request(type, body, replyType) {
    const request = this.send(type, body);
    if (!request) return Promise.reject(new DisconnectedError(`not connected: ${typeName(type)} not sent`));
    return new Promise((resolve, reject) => this.pending.set(request, { resolve, reject, replyType }));
  }

  /** Answers the server's token request; `remember` keeps the token in sessionStorage for this tab. */
  submitToken(token, remember) {
    this.token = token;
    this.waitingForToken = false;
    if (remember) this.storage?.setItem(TOKEN_KEY, token);
    else this.storage?.removeItem(TOKEN_KEY);
    if (this.ws && this.ws.readyState === 1 && this.serverHello) this.sendRaw(encode(Type.Auth, { token }, this.takeRequestId()));
    else this.reconnectNow();
  }

  // ---- internals ----

  takeRequestId() {
    const id = this.nextRequest;
    this.nextRequest = id >= 0xffffffff ? 1 : id + 1;
    return id;
  }

  sendRaw(buffer) {
    if (this.ws && this.ws.readyState === 1) this.ws.send(buffer);
  }

  // Only a pending retry is cleared (Node 18's fake timers, which the unit tests use, lose
  // every later timeout after a clearTimeout(null)).
  cancelRetry() {
    if (this.retryTimer !== null) clearTimeout(this.retryTimer);
    this.retryTimer = null;
  }

  emit(name, detail) {
    this.dispatchEvent(new CustomEvent(name, { detail }));
  }

  setState(state, reason = '', retryInMs = 0) {
    this.state = state;
    this.emit('state', { state, reason, retryInMs });
  }

  dropSocket() {
    const ws = this.ws;
    this.ws = null;
    if (!ws) return;
    ws.onopen = ws.onmessage = ws.onclose = null;
    try { ws.close(1000); } catch { /* already closing */ }
    this.rejectPending('disconnected');
  }

  rejectPending(why) {
    for (const { reject } of this.pending.values()) reject(new DisconnectedError(why));
    this.pending.clear();
  }

  onData(data) {
    if (!(data instanceof ArrayBuffer)) {
      this.emit('error', new ProtocolError('BadPayload', 'the server sent a text message; the protocol is binary'));
      return;
    }
    let m;
    try {
      m = decode(data);
    } catch (e) {
      if (!(e instanceof ProtocolError)) throw e;
      this.emit('error', new ProtocolError(e.code, `malformed message from the server: ${e.message}`));
      if (FRAMING_ERRORS.has(e.code)) {
        this.sendRaw(encode(Type.Error, { code: ErrorCode[e.code], fatal: true, offendingType: 0, message: e.message.slice(0, 1000) }, 0));
        this.ws.close(1002);
      }
      return;
    }
    this.onMessage(m);
  }

  onMessage(m) {
    switch (m.type) {
      case Type.Hello: return this.onHello(m.body);
      case Type.AuthOk: return this.onReady();
      case Type.Error: return this.onError(m);
      case Type.Bye:
        // An idle timeout means nobody is watching: wait for the Reconnect button.
        if (m.body.reason === 2) this.autoReconnect = false;
        this.byeReason = ['the server said goodbye', 'the server is shutting down', 'idle timeout'][m.body.reason] ?? `Bye ${m.body.reason}`;
        return;
      default: break;
    }
    const p = this.pending.get(m.request);
    if (p && p.replyType === m.type) {
      this.pending.delete(m.request);
      p.resolve(m.body);
    }
    this.emit('message', m);
  }

  onHello(h) {
    if (h.versionMin > 1 || h.versionMax < 1) {
      this.autoReconnect = false;
      this.emit('error', new Error(`the server speaks protocol versions ${h.versionMin}..${h.versionMax}; this page speaks 1`));
      this.ws.close(1002);
      return;
    }
    this.serverHello = h;
    if (!(h.capabilities & Capability.AuthRequired)) return this.onReady();
    const token = this.token ?? this.storage?.getItem(TOKEN_KEY);
    if (token) {
      this.token = token;
      this.sendRaw(encode(Type.Auth, { token }, this.takeRequestId()));
    } else {
      this.askForToken(false, 'this server requires an access token');
    }
  }

  onReady() {
    this.attempt = 0;
    this.setState('ready');
  }

  askForToken(failed, message) {
    this.waitingForToken = true;
    this.setState('auth', message);
    this.emit('auth', { failed, message });
  }

  onError(m) {
    const err = new ServerError(m.body, m.request);
    if (m.body.code === ErrorCode.AuthFailed || m.body.code === ErrorCode.NotAuthenticated) {
      // Fatal: the server closes. Forget the token and wait for a new one rather than retry it.
      this.token = null;
      this.storage?.removeItem(TOKEN_KEY);
      this.askForToken(m.body.code === ErrorCode.AuthFailed,
        m.body.code === ErrorCode.AuthFailed ? 'the server rejected this token' : 'the server requires a token');
      return;
    }
    const p = this.pending.get(m.request);
    if (p) {
      this.pending.delete(m.request);
      p.reject(err);
    }
    if (m.body.fatal) this.fatalReason = err.message;
    this.emit('error', err);
  }

  onClosed(ws, reason) {
    if (ws !== this.ws) return;
    this.ws = null;
    this.rejectPending('disconnected');
    const why = this.fatalReason || this.byeReason || reason;
    this.fatalReason = this.byeReason = null;
    if (this.waitingForToken) {
      this.setState('auth', why);
      return;
    }
    if (!this.autoReconnect) {
      this.setState('disconnected', why);
      return;
    }
    const base = Math.min(BACKOFF_MAX_MS, BACKOFF_FIRST_MS * 2 ** this.attempt);
    const delay = Math.round(base * (0.75 + 0.5 * Math.random()));
    this.attempt += 1;
    this.setState('disconnected', why, delay);
    this.retryTimer = setTimeout(() => this.connect(), delay);
  }
}

function closeReason(e) {
  if (e && e.reason) return e.reason;
  if (e && e.code === 1006) return 'the connection was lost';
  return `the connection closed${e && e.code ? ` (${e.code})` : ''}`;
}
