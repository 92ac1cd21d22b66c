// vdyn-foxglove as Foxglove and Lichtblick see it, through their own protocol client
// (@foxglove/ws-protocol): a real server on the facility world driven by vdyn-input's demo drive,
// one bridge with input off and one that allows it.
"use strict";
const { test, before, after } = require("node:test");
const assert = require("node:assert/strict");
const WebSocket = require("ws");
const h = require("./harness");

let b;        // the bridge with input off
let watcher;  // a client subscribed to everything

before(async () => {
  h.server();
  h.demoDrive();
  b = await h.bridge("bridge");
  watcher = new h.Client(b.url);
  await watcher.opened;
  await h.until(() => watcher.byTopic.has("/vehicle/1/state"), 20000, "vehicle 1's channels advertised");
  for (const topic of watcher.byTopic.keys()) watcher.subscribe(topic);
  // The car moving: a second of states after it passed 20 km/h.
  await h.until(() => watcher.of("/vehicle/1/state").filter((s) => s.msg.speed_kmh > 20).length > 1000,
                30000, "a second of driving above 20 km/h");
});

after(async () => {
  watcher.close();
  await h.stopGracefully();
});

test("both subprotocols are accepted and the chosen one is echoed", async () => {
  for (const offered of [["foxglove.websocket.v1"], ["foxglove.sdk.v1"], ["foxglove.sdk.v1", "foxglove.websocket.v1"]]) {
    const c = new h.Client(b.url, offered);
    await c.opened;
    assert.equal(c.ws.protocol, offered[0]);
    await h.until(() => c.info && c.byTopic.has("/vehicle/1/state"), 5000, `server info and channels (${offered})`);
    c.close();
  }
  // A WebSocket that offers no Foxglove subprotocol is refused with the reason.
  const other = new WebSocket(b.url, ["something.else"]);
  const refused = await new Promise((resolve) => {
    other.on("unexpected-response", (req, res) => {
      let body = "";
      res.on("data", (d) => (body += d));
      res.on("end", () => resolve({ status: res.statusCode, body }));
    });
    other.on("open", () => resolve({ status: 101 }));
    other.on("error", () => {});
  });
  assert.equal(refused.status, 400);
  assert.match(refused.body, /foxglove\.websocket\.v1 or foxglove\.sdk\.v1/);
});

test("server info names the capabilities, the session and nothing this bridge does not offer", async () => {
  const i = watcher.info;
  assert.equal(i.name, "vdyn-foxglove");
  for (const cap of ["time", "parameters", "parametersSubscribe"]) assert.ok(i.capabilities.includes(cap), cap);
  assert.ok(!i.capabilities.includes("clientPublish"), "client publish is off without --allow-input");
  assert.match(i.sessionId, /^\d+$/);
  const again = new h.Client(b.url);
  await h.until(() => again.info, 5000, "server info");
  assert.equal(again.info.sessionId, i.sessionId, "one session id per bridge run");
  again.close();
});

test("every advertised schema decodes every message", async () => {
  // Each message decoded by its channel's schema (the harness throws if one does not decode or
  // verify), and every kind of channel has delivered.
  for (const topic of ["/vehicle/1/state", "/vehicle/1/tf", "/vehicle/1/scene", "/vdyn/world"]) {
    assert.ok(watcher.of(topic).length > 0, `${topic}: nothing arrived`);
  }
  await h.until(() => watcher.of("/vdyn/diagnostics").length > 0, 5000, "diagnostics");
  await h.until(() => watcher.of("/vdyn/events").length > 0, 5000, "session events");
  assert.deepEqual(watcher.errors, []);
  let decoded = 0;
  for (const list of watcher.messages.values()) for (const m of list) decoded += m.msg ? 1 : 0;
  assert.ok(decoded > 1000, `${decoded} messages decoded`);
  const names = new Set([...watcher.channels.values()].map((c) => c.schemaName));
  for (const n of ["vdyn.pb.VehicleState", "foxglove.FrameTransforms", "foxglove.SceneUpdate", "vdyn.pb.Diagnostics", "vdyn.pb.SessionEvent"]) {
    assert.ok(names.has(n), n);
  }
  // The terrain: triangles of every mesh of the world, sent once to this subscriber.
  const world = watcher.of("/vdyn/world");
  assert.equal(world.length, 1);
  const tris = world[0].msg.entities[0].triangles;
  assert.ok(tris.length >= 5 && tris.every((t) => t.points.length >= 3 && t.indices.length % 3 === 0));
  // States at full rate: consecutive steps, one log time (the simulation clock) each.
  const states = watcher.of("/vehicle/1/state").slice(-500);
  for (let k = 1; k < states.length; ++k) {
    assert.equal(states[k].msg.step, states[k - 1].msg.step + 1);
    assert.equal(states[k].logTime, states[k].msg.sim_time_ns);
  }
});

test("time messages carry the simulation clock", async () => {
  const n = watcher.times.length;
  await h.until(() => watcher.times.length > n + 30, 5000, "30 time messages");
  const t = watcher.times.slice(n);
  for (let k = 1; k < t.length; ++k) assert.ok(t[k] >= t[k - 1], "time goes forward");
  // A time message is the newest state the bridge has; the states behind it in the client's queue
  // arrive after it (on a loaded machine seconds later), so wait for them, then find that very step.
  const last = t.at(-1);
  await h.until(() => watcher.of("/vehicle/1/state").at(-1).logTime >= last, 30000, `a state at ${last} ns`);
  // Within 0.2 s of a received state (the one at exactly that time may have been dropped from a
  // slow client's queue); a wall-clock time would be 1.7e18 ns away.
  const near = watcher.of("/vehicle/1/state").some((s) => Math.abs(s.logTime - last) < 0.2e9);
  assert.ok(near, `time ${last} ns is the simulation time of a received state`);
  assert.ok(t.every((x) => x % 1000000 === 0), "times are on the 1 kHz step grid");
});

test("the scene's transforms and force arrows follow the drive", async () => {
  const states = new Map(watcher.of("/vehicle/1/state").map((s) => [s.logTime, s.msg]));
  const tfs = watcher.of("/vehicle/1/tf").filter((t) => states.has(t.logTime));
  const scenes = watcher.of("/vehicle/1/scene").filter((s) => states.has(s.logTime));
  assert.ok(tfs.length > 60 && scenes.length > 60, `${tfs.length} transforms, ${scenes.length} scenes matched to states`);
  const scale = 0.5 / 1000;  // m per N, the viewer's default
  let vertical = 0;
  for (const { logTime, msg } of tfs) {
    const s = states.get(logTime);
    const body = msg.transforms.find((t) => t.child_frame_id === "vehicle/1/body");
    assert.equal(body.parent_frame_id, "world");
    for (const k of ["x", "y", "z"]) assert.ok(Math.abs(body.translation[k] - s.p_wt_w[k]) < 1e-9);
    const wheels = msg.transforms.filter((t) => t.parent_frame_id === "vehicle/1/body");
    assert.deepEqual(wheels.map((t) => t.child_frame_id), ["LF", "RF", "LR", "RR"].map((w) => `vehicle/1/wheel/${w}`));
  }
  for (const { logTime, msg } of scenes) {
    const s = states.get(logTime);
    const forces = msg.entities.find((e) => e.id === "vehicle/1/forces");
    assert.equal(forces.frame_id, "world");
    assert.equal(forces.arrows.length, 18);
    for (let w = 0; w < 4; ++w) {
      const spring = forces.arrows[4 * w];
      // At the contact point B, as long as the spring force times the scale, in the legend's green.
      for (const k of ["x", "y", "z"]) assert.ok(Math.abs(spring.pose.position[k] - s.wheels[w].p_b_w[k]) < 1e-9);
      const length = spring.shaft_length + spring.head_length;
      assert.ok(Math.abs(length - s.wheels[w].fp * scale) < 1e-9, `spring arrow ${length} m for ${s.wheels[w].fp} N`);
      assert.deepEqual([spring.color.r, spring.color.g, spring.color.b].map((c) => Math.round(c * 255)), [40, 200, 60]);
      // The arrow's direction (+X turned by its orientation) has the upward part n_z of the normal.
      const q = spring.pose.orientation;
      const dz = 2 * (q.x * q.z - q.w * q.y);
      vertical += length / scale * dz;
    }
  }
  // Over the drive the body's mean vertical acceleration is ~0, so the springs carry the weight:
  // the mean of the four spring forces' vertical parts is m g (no aerodynamic lift in the model).
  watcher.params.length = 0;
  watcher.client.getParameters(["vehicle/1/mass", "vehicle/1/gravity"], "weight");
  const p = await h.until(() => watcher.params.find((x) => x.id === "weight"), 5000, "mass and gravity");
  const m = p.parameters.find((x) => x.name === "vehicle/1/mass").value;
  const g = p.parameters.find((x) => x.name === "vehicle/1/gravity").value;
  const mean = vertical / scenes.length;
  assert.ok(Math.abs(mean - m * g) < 0.05 * m * g, `mean spring load ${mean.toFixed(0)} N, m g = ${(m * g).toFixed(0)} N`);
  // The car moved, and the transforms with it.
  const first = tfs[0].msg.transforms[0].translation, last = tfs.at(-1).msg.transforms[0].translation;
  assert.ok(Math.hypot(last.x - first.x, last.y - first.y) > 5, "the body moved more than 5 m");
});

test("a refused parameter comes back with the server's reason; an accepted one is applied", async () => {
  watcher.status.length = 0;
  watcher.params.length = 0;
  watcher.client.setParameters([{ name: "vehicle/1/mass", value: -5, type: "float64" }], "bad");
  const refusal = await h.until(() => watcher.status.find((s) => s.level === 2), 10000, "a status error");
  assert.match(refusal.message, /vehicle\/1\/mass: refused by server '[^']+': .*-5/);
  const back = await h.until(() => watcher.params.find((x) => x.id === "bad"), 5000, "the current value");
  assert.ok(back.parameters[0].value > 0, "the mass as it is");
  watcher.client.subscribeParameterUpdates(["vehicle/1/mass"]);
  watcher.client.setParameters([{ name: "vehicle/1/mass", value: 1600, type: "float64" }], "good");
  const ok = await h.until(() => watcher.params.find((x) => x.id === "good"), 10000, "the accepted value");
  assert.equal(ok.parameters[0].value, 1600);
  // The server publishes the new parameters; the subscribed update carries them.
  await h.until(() => watcher.params.find((x) => !x.id && x.parameters.some((q) => q.name === "vehicle/1/mass" && q.value === 1600)),
                10000, "the parameter update");
  // One name twice: the answer is the value in force, the last (both were echoed).
  watcher.client.setParameters([{ name: "vehicle/1/mass", value: 1650, type: "float64" },
                                { name: "vehicle/1/mass", value: 1700, type: "float64" }], "twice");
  const twice = await h.until(() => watcher.params.find((x) => x.id === "twice"), 10000, "the answer");
  assert.deepEqual(twice.parameters.map((q) => [q.name, q.value]), [["vehicle/1/mass", 1700]]);
  // A whole number for a float64 parameter: the answer is the value as the vehicle holds it,
  // typed (it came back as the client wrote it, without a type).
  watcher.client.setParameters([{ name: "vehicle/1/mass", value: 1710 }], "whole");
  const whole = await h.until(() => watcher.params.find((x) => x.id === "whole"), 10000, "the answer");
  assert.deepEqual(whole.parameters.map((q) => [q.name, q.value, q.type]), [["vehicle/1/mass", 1710, "float64"]]);
  // Names that are not vehicle parameters, and values of the wrong type, are refused here.
  watcher.status.length = 0;
  watcher.client.setParameters([{ name: "vehicle/1/no_such_thing", value: 1 }, { name: "vehicle/1/model", value: 3 }], "names");
  await h.until(() => watcher.status.filter((s) => s.level === 2).length >= 2, 5000, "two refusals");
  assert.match(watcher.status[0].message, /vehicle\/1\/no_such_thing: no parameter 'no_such_thing'/);
  assert.match(watcher.status[1].message, /'model' takes one of VEHICLE_MODEL_UNSPECIFIED/);
});

test("driving from a client is refused unless allowed, then takes the vehicle at its strength", async () => {
  const c = new h.Client(b.url);
  await h.until(() => c.info, 5000, "server info");
  const ch = c.client.advertise({ topic: "/vehicle/1/input", encoding: "json", schemaName: "vdyn.pb.DriverInput" });
  await h.until(() => c.status.find((s) => s.level === 2), 5000, "a refusal");
  assert.match(c.status[0].message, /client publish is off/);
  c.client.sendMessage(ch, new TextEncoder().encode(JSON.stringify({ steer: 0.1 })));
  await h.until(() => c.status.filter((s) => s.level === 2).length >= 2, 5000, "input ignored, said");
  assert.match(c.status[1].message, /without --allow-input/);
  c.close();

  const open = await h.bridge("bridge-input", ["--allow-input", "--input-strength", "20"]);
  const d = new h.Client(open.url);
  await h.until(() => d.info && d.byTopic.has("/vehicle/1/state"), 20000, "server info");
  assert.ok(d.info.capabilities.includes("clientPublish"));
  assert.deepEqual(d.info.supportedEncodings, ["json", "protobuf"]);
  d.subscribe("/vehicle/1/state");
  const input = d.client.advertise({ topic: "/vehicle/1/input", encoding: "json", schemaName: "vdyn.pb.DriverInput" });
  const send = setInterval(() => d.client.sendMessage(input, new TextEncoder().encode(JSON.stringify({ steer: 0.2, throttle: 0.3 }))), 20);
  try {
    const s = await h.until(() => d.of("/vehicle/1/state").find((x) => /^foxglove-/.test(x.msg.input.source_id)), 15000,
                            "a state driven by the client's input");
    assert.ok(Math.abs(s.msg.input.steer - 0.2) < 1e-12);
  } finally {
    clearInterval(send);
  }
  // Bad input is said, not sent.
  d.client.sendMessage(input, new TextEncoder().encode("{\"steer\": \"left\"}"));
  await h.until(() => d.status.find((x) => x.level === 2 && /is not a vdyn\.pb\.DriverInput/.test(x.message)), 5000, "a refusal");
  // A number that is not finite is refused by name (it was clamped to 0 and driven), and one past
  // its limit is clamped and said (a warning). A client hears of its input at most once a second.
  await new Promise((r) => setTimeout(r, 1100));
  d.client.sendMessage(input, new TextEncoder().encode(JSON.stringify({ steer: "NaN", throttle: 0.1 })));
  await h.until(() => d.status.find((x) => x.level === 2 && /driver input for vehicle 1 refused: steer is NaN/.test(x.message)),
                5000, "a non-finite input refused");
  await new Promise((r) => setTimeout(r, 1100));
  d.client.sendMessage(input, new TextEncoder().encode(JSON.stringify({ throttle: 7 })));
  await h.until(() => d.status.find((x) => x.level === 1 && /throttle must be in \[-1, 1\], got 7: clamped/.test(x.message)),
                5000, "a clamped input said");
  // Channels that drive nothing are refused by name: vehicle 0, another schema (both were taken).
  d.client.advertise({ topic: "/vehicle/0/input", encoding: "json", schemaName: "vdyn.pb.DriverInput" });
  d.client.advertise({ topic: "/vehicle/1/input", encoding: "json", schemaName: "foo.Bar" });
  await h.until(() => d.status.find((x) => /advertise: \/vehicle\/0\/input: vehicle id must be in \[1, 4294967295\], got 0/.test(x.message)),
                5000, "vehicle 0 refused");
  await h.until(() => d.status.find((x) => /advertise: \/vehicle\/1\/input: schema 'foo\.Bar', expected vdyn\.pb\.DriverInput/.test(x.message)),
                5000, "another schema refused");
  d.close();
});

test("bad client messages get a status error that says what is wrong", async () => {
  const c = new h.Client(b.url);
  await h.until(() => c.info, 5000, "server info");
  c.ws.send("this is not JSON");
  c.ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: "two" }] }));
  c.ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: 99999 }] }));
  c.ws.send(JSON.stringify({ op: "fetchAsset", uri: "x", requestId: 1 }));
  await h.until(() => c.status.length >= 4, 5000, "four status errors");
  assert.match(c.status[0].message, /bad message: not JSON/);
  assert.match(c.status[1].message, /subscriptions\[0\]\.channelId is not a whole number/);
  assert.match(c.status[2].message, /no channel 99999 is advertised/);
  assert.match(c.status[3].message, /op 'fetchAsset' is not offered/);
  // The connection stays usable.
  c.subscribe("/vehicle/1/tf");
  await h.until(() => c.of("/vehicle/1/tf").length > 3, 5000, "transforms after the errors");
  c.close();
});

test("vehicles are advertised as they come and unadvertised as they go", async () => {
  const other = h.server(["--vehicle-ids", "7", "--server-id", "second", "--duration", "3"]);
  await h.until(() => watcher.byTopic.has("/vehicle/7/state"), 20000, "vehicle 7 advertised");
  await other.exited;
  await h.until(() => (watcher.unadvertised || []).includes("/vehicle/7/state"), 10000, "vehicle 7 unadvertised");
  assert.ok(watcher.byTopic.has("/vehicle/1/state"), "vehicle 1 stays");
});

test("--state-hz decimates each state channel and --scene-hz sets the scene's rate", async () => {
  const slow = await h.bridge("bridge-rates", ["--state-hz", "50", "--scene-hz", "10"]);
  const c = new h.Client(slow.url);
  await h.until(() => c.byTopic.has("/vehicle/1/state"), 20000, "vehicle 1's channels");
  c.subscribe("/vehicle/1/state");
  c.subscribe("/vehicle/1/tf");
  await h.until(() => c.of("/vehicle/1/state").length > 60 && c.of("/vehicle/1/tf").length > 12, 20000, "states and transforms");
  const gaps = (list) => list.slice(1).map((m, k) => (m.logTime - list[k].logTime) / 1e6);
  // States never closer than 20 ms of simulation time (a step's tolerance) and typically 20 ms
  // apart, transforms about 100 ms apart: latest only, built from the newest state at each tick of
  // the bridge's clock. A tick the machine delays leaves a longer gap (300 ms at load 8 beside the
  // sanitizer build, 2026-12-05), so the typical gap is judged by the median, not every gap.
  const sg = gaps(c.of("/vehicle/1/state"));
  for (const g of sg) assert.ok(g >= 19.5, `states ${g} ms apart: faster than --state-hz 50`);
  const sMedian = [...sg].sort((a, b) => a - b)[Math.floor(sg.length / 2)];
  assert.ok(sMedian <= 40, `states ${sMedian} ms apart (median)`);
  const tf = gaps(c.of("/vehicle/1/tf")).sort((a, b) => a - b);
  const median = tf[Math.floor(tf.length / 2)];
  assert.ok(median > 80 && median < 120, `transforms ${median} ms apart (median)`);
  c.close();
});

test("wss:// and https:// with a certificate and key", async () => {
  const { execFileSync } = require("child_process");
  const path = require("path");
  const https = require("https");
  const key = path.join(h.work, "key.pem"), cert = path.join(h.work, "cert.pem");
  execFileSync("openssl", ["req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert,
                           "-subj", "/CN=127.0.0.1", "-days", "2"], { stdio: "ignore" });
  const secure = await h.bridge("bridge-tls", ["--tls-cert", cert, "--tls-key", key]);
  assert.match(secure.url, /^wss:\/\//);
  const c = new h.Client(secure.url, ["foxglove.sdk.v1"], { rejectUnauthorized: false });
  await c.opened;
  await h.until(() => c.info && c.byTopic.has("/vehicle/1/state"), 20000, "server info over wss");
  c.subscribe("/vehicle/1/state");
  await h.until(() => c.of("/vehicle/1/state").length > 100, 10000, "states over wss");
  c.close();
  const page = await new Promise((resolve, reject) => {
    https.get(`https://127.0.0.1:${secure.port}/`, { rejectUnauthorized: false }, (res) => {
      let body = "";
      res.on("data", (d) => (body += d));
      res.on("end", () => resolve({ status: res.statusCode, body }));
    }).on("error", reject);
  });
  assert.equal(page.status, 200);
  assert.match(page.body, /<script src="three\.min\.js"><\/script>/);
  // A key that is not a key is refused at the start, naming the file.
  const bad = h.start("bridge-badkey", h.bin.foxglove, ["--domain", h.domain, "--port", "0", "--tls-cert", cert, "--tls-key", cert]);
  assert.equal(await bad.exited, 1);
  assert.match(bad.lines.join("\n"), /cert\.pem: not a usable PEM private key/);
});
