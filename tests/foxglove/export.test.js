// `vdyn-recorder export FILE --foxglove OUT.mcap` on a live recording, read back by the MCAP
// project's own reader (@mcap/core): the original channels unchanged, and the scene channels'
// foxglove.SceneUpdate and foxglove.FrameTransforms messages decode by the schemas in the file
// and match the recorded states.
"use strict";
const { test, after } = require("node:test");
const assert = require("node:assert/strict");
const fs = require("fs");
const path = require("path");
const { McapIndexedReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");
const h = require("./harness");

after(async () => await h.stopGracefully());

async function read(file, handlers) {
  const bytes = fs.readFileSync(file);
  const readable = { size: async () => BigInt(bytes.length), read: async (o, n) => bytes.subarray(Number(o), Number(o + n)) };
  const r = await McapIndexedReader.Initialize({ readable, decompressHandlers: handlers });
  const types = new Map();
  const type = (schemaId) => {
    if (!types.has(schemaId)) {
      const s = r.schemasById.get(schemaId);
      const set = descriptor.FileDescriptorSet.decode(s.data);
      types.set(schemaId, protobuf.Root.fromDescriptor(set).lookupType(s.name));
    }
    return types.get(schemaId);
  };
  const byTopic = new Map();
  for await (const m of r.readMessages({ validateCrcs: true })) {
    const ch = r.channelsById.get(m.channelId);
    const t = type(ch.schemaId);
    const msg = t.decode(m.data);
    const err = t.verify(msg);
    if (err) throw new Error(`${file}: a ${t.fullName} on ${ch.topic} does not verify: ${err}`);
    if (!byTopic.has(ch.topic)) byTopic.set(ch.topic, []);
    byTopic.get(ch.topic).push({ logTime: m.logTime, schema: r.schemasById.get(ch.schemaId).name, channel: ch,
                                 msg: t.toObject(msg, { longs: Number, enums: String, defaults: true }) });
  }
  return byTopic;
}

test("an exported recording holds the recording unchanged and Foxglove's scene of it", async () => {
  const rec = path.join(h.work, "drive.mcap");
  const out = path.join(h.work, "drive-foxglove.mcap");
  const recorder = h.start("recorder", h.bin.recorder, ["record", rec, "--domain", h.domain, "--duration", "6", "--no-status"]);
  h.server(["--duration", "5"]);
  h.demoDrive();
  assert.equal(await recorder.exited, 0);
  const exp = h.start("export", h.bin.recorder, ["export", rec, "--foxglove", out]);
  assert.equal(await exp.exited, 0, exp.lines.join("\n"));
  assert.match(exp.lines.join("\n"), /added \d+ scenes with their transforms \(1 vehicles, 60 Hz\) and 1 terrain/);
  // Never over the recording itself.
  const over = h.start("export-over", h.bin.recorder, ["export", rec, "--foxglove", rec]);
  assert.equal(await over.exited, 2);

  const handlers = await loadDecompressHandlers();
  const [a, b] = [await read(rec, handlers), await read(out, handlers)];
  for (const [topic, list] of a) {
    const copy = b.get(topic);
    assert.ok(copy, `${topic} is in the copy`);
    assert.equal(copy.length, list.length, `${topic}: as many messages`);
    assert.deepEqual(copy[0].channel.metadata, list[0].channel.metadata);
    assert.equal(copy[0].schema, list[0].schema);
  }
  // Several states may share a log time (the recorder takes a step batch at once): a scene is
  // built from the first of its slot.
  const states = new Map();
  for (const s of a.get("vdyn/state/1")) if (!states.has(s.logTime)) states.set(s.logTime, s.msg);
  const scenes = b.get("/vehicle/1/scene"), tfs = b.get("/vehicle/1/tf");
  assert.equal(scenes[0].schema, "foxglove.SceneUpdate");
  assert.equal(tfs[0].schema, "foxglove.FrameTransforms");
  assert.equal(b.get("/vdyn/world")[0].schema, "foxglove.SceneUpdate");
  // 60 a second of log time, each from the state logged at that moment.
  const seconds = Number(a.get("vdyn/state/1").at(-1).logTime - a.get("vdyn/state/1")[0].logTime) / 1e9;
  // At most 60 a second (decimated, not one a state); at least half that, since a recording made
  // on a loaded machine may miss states the scene would be built from (200 in 3.8 s, 2026-12-05).
  assert.ok(scenes.length <= 1.1 * 60 * seconds && scenes.length >= 0.5 * 60 * seconds,
            `${scenes.length} scenes in ${seconds.toFixed(1)} s`);
  for (let k = 0; k < scenes.length; ++k) {
    const s = states.get(tfs[k].logTime);
    assert.ok(s, "a transform at a state's log time");
    const body = tfs[k].msg.transforms[0];
    assert.equal(body.child_frame_id, "vehicle/1/body");
    assert.ok(Math.abs(body.translation.x - s.p_wt_w.x) < 1e-9 && Math.abs(body.translation.y - s.p_wt_w.y) < 1e-9);
    assert.equal(BigInt(body.timestamp.seconds) * 1000000000n + BigInt(body.timestamp.nanos), tfs[k].logTime);
    const forces = scenes[k].msg.entities.find((e) => e.id === "vehicle/1/forces");
    assert.equal(forces.arrows.length, 18);
    assert.ok(Math.abs(forces.arrows[0].pose.position.z - s.wheels[0].p_b_w.z) < 1e-9, "the LF spring arrow at B");
  }

  // The export of an export replaces the earlier scene (it added a second set of scene channels:
  // two scenes of each vehicle in Foxglove).
  const again = path.join(h.work, "drive-foxglove-again.mcap");
  const exp2 = h.start("export-again", h.bin.recorder, ["export", out, "--foxglove", again]);
  assert.equal(await exp2.exited, 0, exp2.lines.join("\n"));
  assert.match(exp2.lines.join("\n"), /had a Foxglove scene of an earlier export \(\d+ messages on 3 channels\): replaced by this one/);
  const c = await read(again, handlers);
  for (const topic of ["/vehicle/1/scene", "/vehicle/1/tf", "/vdyn/world"]) {
    assert.equal(c.get(topic).length, b.get(topic).length, `${topic}: one scene, not two`);
  }
  assert.equal(c.get("vdyn/state/1").length, a.get("vdyn/state/1").length);
});
