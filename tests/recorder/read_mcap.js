// Reads vdyn recordings with the MCAP project's own TypeScript library (@mcap/core), not vdyn's
// C++ reader: a streaming read and an indexed read (summary, chunk and message indexes), every CRC
// checked (chunks, summary, data section), and every message decoded by the schema embedded in the
// file (protobufjs builds the types from the FileDescriptorSet alone). Prints one JSON line per file;
// exits 1 on the first problem.
//   node read_mcap.js FILE.mcap...
"use strict";
const fs = require("fs");
const zlib = require("zlib");
const { McapStreamReader, McapIndexedReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

function fail(file, why) {
  console.error(`${file}: ${why}`);
  process.exit(1);
}

function typeOf(schemas, types, schemaId, file) {
  if (!types.has(schemaId)) {
    const schema = schemas.get(schemaId);
    if (!schema) fail(file, `no schema ${schemaId}`);
    if (schema.encoding !== "protobuf") fail(file, `schema encoding '${schema.encoding}', not protobuf`);
    const set = descriptor.FileDescriptorSet.decode(schema.data);
    const root = protobuf.Root.fromDescriptor(set);
    types.set(schemaId, root.lookupType(schema.name));
  }
  return types.get(schemaId);
}

async function check(file, handlers) {
  const bytes = fs.readFileSync(file);
  // 1. Streaming: every record in order, chunk CRCs validated.
  const stream = new McapStreamReader({ decompressHandlers: handlers, validateCrcs: true });
  stream.append(bytes);
  const schemas = new Map();
  const channels = new Map();
  const types = new Map();
  const perType = {};
  const lastStep = new Map();
  let messages = 0;
  let metadata = [];
  for (let r; (r = stream.nextRecord()); ) {
    if (r.type === "Schema") schemas.set(r.id, r);
    else if (r.type === "Channel") channels.set(r.id, r);
    else if (r.type === "Metadata") metadata.push(r.name);
    else if (r.type === "Message") {
      const ch = channels.get(r.channelId);
      if (!ch) fail(file, `message on unknown channel ${r.channelId}`);
      if (ch.messageEncoding !== "protobuf") fail(file, `message encoding '${ch.messageEncoding}'`);
      const type = typeOf(schemas, types, ch.schemaId, file);
      let msg;
      try {
        msg = type.decode(r.data);
      } catch (e) {
        fail(file, `a message on ${ch.topic} does not decode as ${type.fullName}: ${e.message}`);
      }
      const err = type.verify(msg);
      if (err) fail(file, `a decoded ${type.fullName} does not verify: ${err}`);
      // The decoded state is the state: its step counts up on its channel, its vehicle is the key.
      if (type.fullName === ".vdyn.pb.VehicleState") {
        const step = Number(msg.step || 0);
        const vehicle = msg.vehicle_id ?? msg.vehicleId ?? 0;
        if (String(vehicle) !== ch.metadata.get("vehicle_id")) fail(file, `vehicle ${vehicle} on ${ch.topic}`);
        if (lastStep.has(ch.topic) && step <= lastStep.get(ch.topic)) fail(file, `step ${step} after ${lastStep.get(ch.topic)} on ${ch.topic}`);
        lastStep.set(ch.topic, step);
      }
      perType[type.fullName] = (perType[type.fullName] || 0) + 1;
      messages++;
    }
  }
  if (!stream.done()) fail(file, "the stream reader did not reach the end of the file");
  // 2. Indexed: footer, summary (its CRC checked on opening), statistics, chunk indexes and
  //    message indexes; every message read again through them, CRCs validated.
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers: handlers });
  if (!indexed.statistics) fail(file, "no statistics in the summary");
  if (Number(indexed.statistics.messageCount) !== messages) {
    fail(file, `statistics count ${indexed.statistics.messageCount} messages, the stream had ${messages}`);
  }
  let again = 0;
  let lastTime = -1n;
  const summaryTypes = new Map();  // built again, from the summary's copies of the schemas
  for await (const m of indexed.readMessages({ validateCrcs: true })) {
    const ch = indexed.channelsById.get(m.channelId);
    typeOf(indexed.schemasById, summaryTypes, ch.schemaId, file).decode(m.data);
    if (m.logTime < lastTime) fail(file, "the index gives messages out of log-time order");
    lastTime = m.logTime;
    again++;
  }
  if (again !== messages) fail(file, `the index reaches ${again} messages, the stream ${messages}`);
  // 3. The data section's CRC, computed here over the bytes before the data end record.
  if (indexed.dataSectionCrc) {
    const crc = zlib.crc32 ? zlib.crc32(bytes.subarray(0, Number(indexed.dataEndOffset)))
                           : fail(file, "this node has no zlib.crc32");
    if (crc !== indexed.dataSectionCrc) fail(file, `data section CRC ${crc}, the file says ${indexed.dataSectionCrc}`);
  } else if (!process.env.NO_DATA_CRC_EXPECTED) {
    fail(file, "the data end record has no CRC");
  }
  const compression = [...new Set(indexed.chunkIndexes.map((c) => c.compression || "none"))];
  console.log(JSON.stringify({ file, messages, chunks: indexed.chunkIndexes.length, compression,
                               perType, topics: [...new Set([...channels.values()].map((c) => c.topic))].length,
                               metadata }));
}

(async () => {
  const handlers = await loadDecompressHandlers();
  const files = process.argv.slice(2);
  if (files.length === 0) fail("read_mcap.js", "no file given");
  for (const f of files) await check(f, handlers);
})().catch((e) => fail("read_mcap.js", e.stack || String(e)));
