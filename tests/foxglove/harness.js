// What the vdyn-foxglove tests share: vdyn's programs as child processes on the test's DDS domain
// (killed when the test file ends, whatever happens), a Foxglove protocol client as Foxglove and
// Lichtblick use it (@foxglove/ws-protocol over the `ws` package), every channel's messages
// decoded by the schema it advertises (protobufjs builds the types from the FileDescriptorSet
// alone), and waits on events, bounded, that say what did not arrive.
"use strict";
const { spawn } = require("child_process");
const fs = require("fs");
const path = require("path");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const build = process.env.VDYN_BUILD;
const domain = process.env.VDYN_DOMAIN;
const work = process.env.VDYN_WORK;
const children = [];

const bin = {
  server: path.join(build, "server/vdyn-server"),
  input: path.join(build, "clients/wheel_input/vdyn-input"),
  foxglove: path.join(build, "clients/foxglove/vdyn-foxglove"),
  recorder: path.join(build, "clients/recorder/vdyn-recorder"),
};

// Starts a program with its output in WORK/NAME.log; `lines` gets every line it prints.
function start(name, program, args) {
  const log = fs.createWriteStream(path.join(work, `${name}.log`));
  const child = spawn(program, args, { stdio: ["ignore", "pipe", "pipe"] });
  child.lines = [];
  child.listeners = [];
  let rest = "";
  const take = (chunk) => {
    log.write(chunk);
    rest += chunk.toString();
    let nl;
    while ((nl = rest.indexOf("\n")) >= 0) {
      const line = rest.slice(0, nl);
      rest = rest.slice(nl + 1);
      child.lines.push(line);
      for (const l of child.listeners) l(line);
    }
  };
  child.stdout.on("data", take);
  child.stderr.on("data", take);
  child.exited = new Promise((resolve) => child.on("exit", (code, signal) => resolve(code ?? 128)));
  children.push(child);
  return child;
}

function stopAll() {
  for (const c of children) {
    if (c.exitCode === null) c.kill("SIGKILL");
  }
}
process.on("exit", stopAll);

// SIGINT to every program still running (each prints its summary into its log), SIGKILL to any
// still there after 5 s.
async function stopGracefully() {
  const running = children.filter((c) => c.exitCode === null && c.signalCode === null);
  for (const c of running) c.kill("SIGINT");
  await Promise.race([Promise.all(running.map((c) => c.exited)), new Promise((r) => setTimeout(r, 5000))]);
  stopAll();
}

// Resolves with the first line (printed so far or later) for which `match` returns a value.
function waitForLine(child, match, ms, what) {
  return new Promise((resolve, reject) => {
    for (const l of child.lines) {
      const m = match(l);
      if (m) return resolve(m);
    }
    const timer = setTimeout(() => reject(new Error(`no ${what} within ${ms} ms; the log:\n${child.lines.slice(-20).join("\n")}`)), ms);
    child.listeners.push((l) => {
      const m = match(l);
      if (m) {
        clearTimeout(timer);
        resolve(m);
      }
    });
    child.exited.then((code) => reject(new Error(`exited (${code}) before ${what}; the log:\n${child.lines.slice(-20).join("\n")}`)));
  });
}

// Polls `test` every 10 ms until it returns something truthy, at most `ms`.
function until(test, ms, what) {
  return new Promise((resolve, reject) => {
    const t0 = Date.now();
    const tick = () => {
      let v;
      try {
        v = test();
      } catch (e) {
        return reject(e);
      }
      if (v) return resolve(v);
      if (Date.now() - t0 > ms) return reject(new Error(`${what}: not within ${ms} ms`));
      setTimeout(tick, 10);
    };
    tick();
  });
}

function server(extra = []) {
  return start(`server${extra.length ? "-" + extra.join("").replace(/[^a-z0-9]/gi, "").slice(0, 20) : ""}`, bin.server,
               ["--domain", domain, "--world", "facility", "--no-status", ...extra]);
}

function demoDrive(extra = []) {
  return start("input", bin.input, ["--domain", domain, "--maneuver", "demo", "--wait", "30", ...extra]);
}

// A vdyn-foxglove on a free port; resolves with the process and its ws:// address.
async function bridge(name, extra = []) {
  const p = start(name, bin.foxglove, ["--domain", domain, "--host", "127.0.0.1", "--port", "0", ...extra]);
  const url = await waitForLine(p, (l) => (l.match(/listening on (wss?:\/\/127\.0\.0\.1:\d+)/) || [])[1], 20000, "listening line");
  return { process: p, url, port: Number(url.split(":").pop()) };
}

// Decodes a channel's messages by its advertised schema.
function decoderFor(channel) {
  if (channel.encoding !== "protobuf" || channel.schemaEncoding !== "protobuf") {
    throw new Error(`${channel.topic}: encoding ${channel.encoding}/${channel.schemaEncoding}`);
  }
  const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
  const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
  return (bytes) => {
    const msg = type.decode(bytes);
    const err = type.verify(msg);
    if (err) throw new Error(`${channel.topic}: a decoded ${channel.schemaName} does not verify: ${err}`);
    return type.toObject(msg, { longs: Number, enums: String, defaults: true });
  };
}

// A Foxglove client: `subprotocols` as the WebSocket offers them. Keeps what arrives: server info,
// channels (by id and topic), status messages, time, and per topic every message decoded.
class Client {
  constructor(url, subprotocols = [FoxgloveClient.SUPPORTED_SUBPROTOCOL], wsOptions = {}) {
    this.ws = new WebSocket(url, subprotocols, wsOptions);
    this.client = new FoxgloveClient({ ws: this.ws });
    this.channels = new Map();
    this.byTopic = new Map();
    this.subs = new Map();
    this.decoders = new Map();
    this.status = [];
    this.params = [];
    this.times = [];
    this.messages = new Map();  // topic -> [{logTime, msg, bytes}]
    this.errors = [];
    this.keep = 100000;  // messages kept per topic
    this.client.on("serverInfo", (i) => (this.info = i));
    this.client.on("status", (s) => this.status.push(s));
    this.client.on("parameterValues", (p) => this.params.push(p));
    this.client.on("time", (t) => this.times.push(Number(t.timestamp)));
    this.client.on("error", (e) => this.errors.push(e));
    this.client.on("advertise", (list) => {
      for (const ch of list) {
        this.channels.set(ch.id, ch);
        this.byTopic.set(ch.topic, ch);
        this.decoders.set(ch.id, decoderFor(ch));
      }
    });
    this.client.on("unadvertise", (ids) => {
      for (const id of ids) {
        const ch = this.channels.get(id);
        if (ch) this.byTopic.delete(ch.topic);
        this.channels.delete(id);
        (this.unadvertised ||= []).push(ch ? ch.topic : id);
      }
    });
    this.client.on("message", (m) => {
      const ch = this.subs.get(m.subscriptionId);
      if (!ch) return this.errors.push(new Error(`message for unknown subscription ${m.subscriptionId}`));
      // Kept as bytes and decoded when first read (a client that decoded everything as it came
      // would be a slow client itself): `msg` throws, and fails the test, when it does not decode.
      const bytes = Uint8Array.from(new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength));
      const decode = this.decoders.get(ch.id);
      let list = this.messages.get(ch.topic);
      if (!list) this.messages.set(ch.topic, (list = []));
      let decoded;
      list.push({ logTime: Number(m.timestamp), size: bytes.length, at: Date.now(),
                  get msg() { return (decoded ??= decode(bytes)); } });
      if (list.length > this.keep) list.splice(0, list.length - this.keep);
    });
    this.opened = new Promise((resolve, reject) => {
      this.ws.once("open", resolve);
      this.ws.once("error", reject);
    });
  }
  subscribe(topic) {
    const ch = this.byTopic.get(topic);
    if (!ch) throw new Error(`no channel ${topic} is advertised (have ${[...this.byTopic.keys()].join(", ")})`);
    const id = this.client.subscribe(ch.id);
    this.subs.set(id, ch);
    return id;
  }
  of(topic) {
    return this.messages.get(topic) || [];
  }
  close() {
    this.ws.terminate();
  }
}

module.exports = { start, stopAll, stopGracefully, waitForLine, until, server, demoDrive, bridge, Client, bin, domain, work, decoderFor };
