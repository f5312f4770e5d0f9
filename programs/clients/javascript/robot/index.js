'use strict';
/**
 * Client for the robotide Robot API (Node.js, standard library only).
 *
 *   const { Robot } = require('robot');
 *   const bot = new Robot();
 *   await bot.drive(0.2, 0);                   // linear m/s, angular rad/s (clamped)
 *   console.log((await bot.sensors()).heading); // compass, degrees
 *   await bot.show('heading', 42);              // appears live on the robot's page
 *   await bot.stop();
 *   await bot.say("I'm home");                  // spoken, and shown on the robot's page
 *   (await bot.scan_barcode()).map((code) => code.text); // the codes in view: ['home']
 *
 * Every method returns a Promise; an error the robot reports rejects it with a RobotError
 * (an Error with `code` and `data`). The connection is made by the first call and
 * authenticated with $ROBOT_TOKEN. While no call is waiting for its answer the connection
 * does not keep Node running, so a program ends by itself when it is done; `bot.close()`
 * ends the connection at once.
 */

const net = require('net');

class RobotError extends Error {
  constructor(message, code, data) {
    super(message);
    this.name = 'RobotError';
    if (code !== undefined) this.code = code;
    if (data !== undefined) this.data = data;
  }
}

class Robot {
  /**
   * @param {string} [address] `unix:/path/to/socket` or `host:port` (default $ROBOT_API)
   * @param {string} [token] the run's token (default $ROBOT_TOKEN)
   */
  constructor(address, token) {
    this.address = address || process.env.ROBOT_API;
    this._token = token || process.env.ROBOT_TOKEN;
    this._socket = null;
    this._ready = null; // Promise of the auth result, made by the first call
    this._pending = new Map(); // id -> {resolve, reject}
    this._nextId = 0;
    this._buffer = '';
    this._failure = null; // once set, every call rejects with it
  }

  /** Connect and authenticate (the first call does it anyway); resolves to {robot, run}. */
  connect() {
    if (this._failure) return Promise.reject(this._failure);
    if (!this._ready) this._ready = this._open();
    return this._ready;
  }

  /** Call a Robot API method by name with positional params. */
  async call(method, ...params) {
    await this.connect();
    return this._request(method, params);
  }

  drive(linear, angular = 0) {
    return this.call('drive', linear, angular);
  }

  stop() {
    return this.call('stop');
  }

  /** All readings: heading (deg), range (m), position {x, y, theta}, ... */
  sensors() {
    return this.call('sensors');
  }

  sensor(name) {
    return this.call('sensor', name);
  }

  capabilities() {
    return this.call('capabilities');
  }

  /** Show a number, a text or an SVG drawing (a string starting with <svg) by name. */
  show(name, value) {
    return this.call('show', name, value);
  }

  /** Send `value` (any JSON) to the programs subscribed to `topic`; resolves to how many. */
  publish(topic, value) {
    return this.call('publish', topic, value);
  }

  /** From now on this connection gets what is published on `topic` (see receive). */
  subscribe(topic) {
    return this.call('subscribe', topic);
  }

  /** The next value published on a subscribed topic; null after `timeout` seconds. */
  receive(topic, timeout = null) {
    return this.call('receive', topic, timeout === undefined ? null : timeout);
  }

  /** Keep `value` (any JSON) under `key` in the memory the robot's programs share. */
  memory_set(key, value) {
    return this.call('memory_set', key, value);
  }

  /** The value kept under `key`, or null. */
  memory_get(key) {
    return this.call('memory_get', key);
  }

  /** Speak `text` (shown on the robot's page too); resolves to {spoken, seconds or reason}. */
  say(text) {
    return this.call('say', text);
  }

  /** The camera's frame now: {jpeg: the JPEG in base64, width, height}. */
  snapshot() {
    return this.call('snapshot');
  }

  /** The barcodes and QR codes in view: an array of {text, format, position}. */
  scan_barcode() {
    return this.call('scan_barcode');
  }

  /**
   * Recognise speech: `seconds` from the microphone, or the WAV file `wav` in the program's
   * folder; `words` (an array) listens for those only. Resolves to {text, words}.
   */
  listen(seconds = 5, wav = null, words = null) {
    return this.call('listen', seconds, wav, words);
  }

  /** End the connection; calls still waiting are rejected. */
  close() {
    const socket = this._socket;
    this._fail(new RobotError('the connection to the robot was closed'));
    if (!socket || socket.destroyed) return Promise.resolve();
    return new Promise((resolve) => {
      // The robot closes its end once it has read ours; if it does not, give up on it.
      const timer = setTimeout(() => socket.destroy(), 1000);
      socket.once('close', () => {
        clearTimeout(timer);
        resolve();
      });
      socket.ref();
      socket.end();
    });
  }

  _open() {
    if (!this.address || !this._token) {
      return Promise.reject(
        new RobotError('ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide')
      );
    }
    let socket;
    if (this.address.startsWith('unix:')) {
      socket = net.createConnection({ path: this.address.slice('unix:'.length) });
    } else {
      const at = this.address.lastIndexOf(':');
      const host = at > 0 ? this.address.slice(0, at) : '127.0.0.1';
      socket = net.createConnection({ host, port: Number(this.address.slice(at + 1)) });
      socket.setNoDelay(true);
    }
    this._socket = socket;
    socket.setEncoding('utf8');
    socket.on('data', (chunk) => this._received(chunk));
    socket.on('error', (err) => {
      this._fail(
        new RobotError(`cannot talk to the robot at ${this.address}: ${err.message}`, err.code)
      );
    });
    socket.on('close', () => {
      this._fail(new RobotError('the robot closed the connection (the run has ended?)'));
    });
    // Written once connected; the calls after it wait for its answer.
    return this._request('auth', [this._token]);
  }

  _request(method, params) {
    if (this._failure) return Promise.reject(this._failure);
    const id = ++this._nextId;
    const line = JSON.stringify({ jsonrpc: '2.0', id, method, params }) + '\n';
    return new Promise((resolve, reject) => {
      this._pending.set(id, { resolve, reject });
      this._socket.ref(); // an answer is awaited: keep Node running
      this._socket.write(line);
    });
  }

  _received(chunk) {
    const lines = (this._buffer + chunk).split('\n');
    this._buffer = lines.pop();
    for (const line of lines) {
      if (line.trim()) this._reply(line);
    }
  }

  _reply(line) {
    let reply;
    try {
      reply = JSON.parse(line);
    } catch (err) {
      this._fail(new RobotError(`the robot sent something that is not JSON: ${err.message}`));
      this._socket.destroy();
      return;
    }
    // Answers come in order: one without an id (a request the robot could not read) is the
    // answer to the oldest call.
    let id = reply && reply.id;
    if (id === null || id === undefined) id = this._pending.keys().next().value;
    const waiting = this._pending.get(id);
    if (!waiting) return;
    this._pending.delete(id);
    if (this._pending.size === 0 && this._socket) this._socket.unref();
    if (reply.error) {
      const { message, code, data } = reply.error;
      waiting.reject(new RobotError(message || 'robot error', code, data));
    } else {
      waiting.resolve(reply.result === undefined ? null : reply.result);
    }
  }

  _fail(error) {
    if (!this._failure) this._failure = error;
    const pending = [...this._pending.values()];
    this._pending.clear();
    for (const { reject } of pending) reject(this._failure);
  }
}

module.exports = { Robot, RobotError };
