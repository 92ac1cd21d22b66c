// A client that stops reading slows nothing else: its queue drops the oldest and says so, the
// server keeps time, another client keeps every state, and once it reads again it gets fresh data
// rather than the backlog.
"use strict";
const { test, after } = require("node:test");
const assert = require("node:assert/strict");
const h = require("./harness");

after(async () => await h.stopGracefully());

test("a stalled client's queue drops and warns while the server and the other clients keep going", async () => {
  h.server(["--vehicle-ids", "1,2,3,4"]);
  h.demoDrive();
  const b = await h.bridge("bridge", ["--queue-kb", "512", "--queue-ms", "1000"]);
  const healthy = new h.Client(b.url);
  const stalled = new h.Client(b.url);
  await h.until(() => [1, 2, 3, 4].every((v) => healthy.byTopic.has(`/vehicle/${v}/state`) && stalled.byTopic.has(`/vehicle/${v}/state`)),
                20000, "four vehicles advertised to both clients");
  healthy.subscribe("/vehicle/1/state");
  await h.until(() => healthy.of("/vehicle/1/state").length > 0, 10000, "the healthy client's first state");
  for (const topic of stalled.byTopic.keys()) stalled.subscribe(topic);
  // Stop reading at once, before any state has come: the kernel grows a socket's receive buffer
  // only as its reader reads, so it stays at its first size (waiting for the first state here
  // let a loaded machine's buffer grow first: 10.87 MB came late at a load of 20, 2026-12-05).
  stalled.ws._socket.pause();
  const pausedAt = Date.now();
  const simAtPause = healthy.of("/vehicle/1/state").at(-1).logTime;
  const before = stalled.status.length;
  await new Promise((resolve) => setTimeout(resolve, 5000));  // the stall itself is the test
  const simAtResume = healthy.of("/vehicle/1/state").at(-1).logTime;
  const wall = (Date.now() - pausedAt) / 1000;
  const resumeIndex = [...stalled.messages.values()].reduce((n, l) => n + l.length, 0);
  stalled.ws._socket.resume();

  // The server kept its clock: simulation time went on with the wall clock (it catches up late
  // ticks and never skips one).
  const sim = (simAtResume - simAtPause) / 1e9;
  assert.ok(sim > 0.7 * wall, `simulation advanced ${sim.toFixed(2)} s in ${wall.toFixed(2)} s`);
  // The other client got vehicle 1's states meanwhile, at their rate (it shares the test's event
  // loop, so a pause of this process could cost it a few).
  const during = healthy.of("/vehicle/1/state").filter((s) => s.logTime >= simAtPause && s.logTime <= simAtResume);
  // Half at least: on a loaded machine this process itself falls behind and the bridge drops the
  // oldest from its queue too (3,370 of 4,530 were seen, 2026-12-05); a stalled client that held
  // the others up would leave them next to none.
  assert.ok(during.length > 0.5 * sim * 1000, `${during.length} states for ${sim.toFixed(2)} s`);

  // The stalled client hears why it lost data...
  const warning = await h.until(() => stalled.status.slice(before).find((s) => s.level === 1), 10000, "a status warning");
  assert.match(warning.message, /reads slower than its subscriptions arrive: \d+ messages? .* dropped, oldest first/);
  // ... and catches up with fresh data, not the backlog: what it got late is at most what the
  // sockets' buffers and its bounded queue held, then the present.
  await h.until(() => {
    const s = stalled.of("/vehicle/1/state").at(-1);
    return s && s.logTime >= healthy.of("/vehicle/1/state").at(-1).logTime - 0.2e9;
  }, 10000, "the stalled client's states at the present again");
  const after = [...stalled.messages.values()].flat().sort((x, y) => x.at - y.at).slice(resumeIndex);
  const stale = after.filter((m) => m.logTime < simAtResume - 0.5e9);
  const staleBytes = stale.reduce((n, m) => n + m.size, 0);
  // The bound: the bridge's queue (512 KB), the most the kernel lets the bridge's send buffer
  // grow to (tcp_wmem's third field, 4 MB on Debian) and 1 MB for this client's receive buffer,
  // paused before it grew. A load of 8 left 3.23 MB late (2026-12-05). The whole stall's backlog,
  // which a bridge that queued without bound would deliver, is about 30 MB (4 vehicles, 1,000
  // states a second, 5 s).
  const wmemMax = Number(require("node:fs").readFileSync("/proc/sys/net/ipv4/tcp_wmem", "utf8").trim().split(/\s+/)[2]);
  const bound = 512 * 1024 + wmemMax + 1024 * 1024;
  assert.ok(staleBytes < bound, `${stale.length} stale messages (${(staleBytes / 1e6).toFixed(2)} MB) after resuming; at most ${(bound / 1e6).toFixed(2)} MB`);
  healthy.close();
  stalled.close();
});

// A client closed for a protocol error that reads nothing more cannot take the close frame: it is
// dropped after the grace period (it kept its --max-clients slot for as long as it stayed
// connected), the log says why (it said "closed", as for a polite client), and its slot is free.
test("a closed client that stops reading is dropped after the grace period and frees its slot", async () => {
  const b = await h.bridge("bridge-grace", ["--max-clients", "1", "--queue-kb", "64"]);
  const c = new h.Client(b.url);
  await h.until(() => c.byTopic.has("/vehicle/1/state"), 20000, "vehicle 1 advertised");
  for (const topic of c.byTopic.keys()) c.subscribe(topic);
  await h.until(() => c.of("/vehicle/1/state").length > 0, 10000, "a first state");
  c.ws._socket.pause();  // reads nothing more: the bridge's sends fill the buffers
  // Until they are full: the bridge's queue for it drops (its status line counts it). Before
  // that, the close frame still fits in the sockets' buffers and goes out at once (a faster
  // machine's run: dropped as "closed", not by the grace period).
  await h.waitForLine(b.process, (l) => { const m = /\| dropped (\d+)/.exec(l); return m && Number(m[1]) > 0; },
                      30000, "the stalled client's queue dropping");
  // A masked frame with the reserved opcode 3: a protocol error (RFC 6455 5.2).
  c.ws._socket.write(Buffer.from([0x83, 0x80, 1, 2, 3, 4]));
  const line = await h.waitForLine(b.process, (l) => (/gone: (WebSocket protocol error.*)/.exec(l) || [])[1],
                                   20000, "the client dropped");
  assert.match(line, /reserved opcode|opcode 3/i);
  assert.match(line, /the close was not taken within 5 s: dropped/);
  const d = new h.Client(b.url);
  await h.until(() => d.info, 10000, "the slot free again: server info for a new client");
  d.close();
  c.ws._socket.destroy();
});
