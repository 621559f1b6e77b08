#!/usr/bin/env node
// Reads an `occmask process` (or `occmask demo`) output the way Foxglove reads it and checks
// what the panels of foxglove/occmask-layout.json need. Usage:
//
//   node check.js FILE.mcap [--layout LAYOUT.json] [--json]
//
// Exit code 0 when every check passes, 1 when one fails, 2 on a usage error.
//
// Foxglove's own libraries do the reading: `@mcap/core`'s McapIndexedReader (the reader of
// Foxglove's and Lichtblick's MCAP data source for files with a summary), `@foxglove/wasm-zstd`
// and `@foxglove/wasm-lz4` for chunk decompression, and `protobufjs` building each channel's
// decoder from the schema's FileDescriptorSet exactly as their `parseChannel` does (Timestamp
// fields renamed sec/nsec, `toObject(..., { defaults: true })`). `@foxglove/schemas` gives the
// reference definition of every foxglove.* schema, which the embedded descriptors must match.

"use strict";

const fs = require("fs");
const path = require("path");
const { McapIndexedReader } = require("@mcap/core");
const protobufjs = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");
const zstd = require("@foxglove/wasm-zstd");
const lz4 = require("@foxglove/wasm-lz4");
const { foxgloveMessageSchemas, generateProto } = require("@foxglove/schemas/internal");

const DEFAULT_LAYOUT = path.join(__dirname, "..", "..", "foxglove", "occmask-layout.json");

// Schemas each panel setting accepts (Foxglove and ROS names, as the panels subscribe by schema).
const IMAGE_SCHEMAS = new Set([
  "foxglove.RawImage",
  "foxglove.CompressedImage",
  "sensor_msgs/msg/Image",
  "sensor_msgs/msg/CompressedImage",
  "sensor_msgs/Image",
  "sensor_msgs/CompressedImage",
]);
const CALIBRATION_SCHEMAS = new Set([
  "foxglove.CameraCalibration",
  "sensor_msgs/msg/CameraInfo",
  "sensor_msgs/CameraInfo",
]);
const ANNOTATION_SCHEMAS = new Set(["foxglove.ImageAnnotations"]);
const THREE_D_TOPIC_SCHEMAS = new Set([
  "foxglove.PoseInFrame",
  "foxglove.PosesInFrame",
  "foxglove.FrameTransform",
  "foxglove.FrameTransforms",
  "tf2_msgs/msg/TFMessage",
  "geometry_msgs/msg/PoseStamped",
  "foxglove.PointCloud",
]);
// Opt-in channels (`process --points`): the layout shows them when the file has them.
const OPTIONAL_TOPICS = new Set(["/groundtruth/pose", "/occmask/points"]);
// foxglove.PackedElementField.NumericType values the point-cloud check needs.
const NUMERIC = { UINT8: 1, FLOAT32: 7 };
// Raw encodings Foxglove's Image panel decodes (decodeRawImage), with bytes per pixel.
const RAW_ENCODING_BYTES = {
  rgb8: 3, bgr8: 3, "8UC3": 3, rgba8: 4, bgra8: 4, mono8: 1, "8UC1": 1, mono16: 2, "16UC1": 2,
  "32FC1": 4, yuv422: 2, uyvy: 2, yuyv: 2, yuv422_yuy2: 2,
  bayer_rggb8: 1, bayer_bggr8: 1, bayer_gbrg8: 1, bayer_grbg8: 1,
};
// Foxglove's PointsAnnotation types (foxglove.PointsAnnotation.Type).
const POINTS_TYPE = { UNKNOWN: 0, POINTS: 1, LINE_LOOP: 2, LINE_STRIP: 3, LINE_LIST: 4 };
// The depth colour-map range should fit the scene's depth: the 99th percentile of valid depth
// inside it and reaching at least this fraction of it. Foxglove's default 0-65535 on TUM depth
// (at most ~6 m = 30000 units, so under half the map: almost black in grey) fails; the layout's
// 0-30000 uses 95% on tum_fr2_desk_50 and 76% on the demo.
const MIN_RANGE_USE = 0.5;
// Unit quaternions: |q| within this of 1 (f64 values written from f64 math).
const QUAT_NORM_TOL = 1e-6;

class Report {
  constructor() {
    this.results = [];
  }
  check(ok, name, detail) {
    this.results.push({ ok: Boolean(ok), name, detail: detail ?? "" });
    return Boolean(ok);
  }
  get failed() {
    return this.results.filter((r) => !r.ok);
  }
}

/** A random-access readable over a file, as Foxglove's remote and local file readers are. */
/** occmask's smallest outlined region (px), contour::ContourOptions::min_area_px. */
const MIN_OUTLINE_AREA_PX = 16;

/** Pixels of the largest 8-connected region of 255s in a mono8 mask. */
function largestRegion(mask) {
  const { width, height, data } = mask;
  const seen = new Uint8Array(width * height);
  let largest = 0;
  const stack = [];
  for (let start = 0; start < width * height; start++) {
    if (data[start] !== 255 || seen[start]) continue;
    seen[start] = 1;
    stack.push(start);
    let size = 0;
    while (stack.length > 0) {
      const i = stack.pop();
      size += 1;
      const x = i % width, y = (i - x) / width;
      for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) {
        const nx = x + dx, ny = y + dy;
        if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
        const j = ny * width + nx;
        if (data[j] === 255 && !seen[j]) { seen[j] = 1; stack.push(j); }
      }
    }
    largest = Math.max(largest, size);
  }
  return largest;
}

function fileReadable(fd, size) {
  return {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      let done = 0;
      while (done < buf.length) {
        const n = fs.readSync(fd, buf, done, buf.length - done, Number(offset) + done);
        if (n === 0) throw new Error(`short read at ${offset}`);
        done += n;
      }
      return new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
    },
  };
}

/** Foxglove's parseChannel for protobuf and JSON channels (the encodings occmask writes). */
function parseChannel(channel, schema) {
  if (channel.messageEncoding === "json") {
    if (schema != undefined && schema.encoding !== "jsonschema") {
      throw new Error(`json message encoding with schema encoding '${schema.encoding}'`);
    }
    const decoder = new TextDecoder();
    const jsonSchema = schema && schema.data.length > 0 ? JSON.parse(decoder.decode(schema.data)) : undefined;
    return { deserialize: (data) => JSON.parse(decoder.decode(data)), jsonSchema };
  }
  if (channel.messageEncoding === "protobuf") {
    if (schema?.encoding !== "protobuf") {
      throw new Error(`protobuf message encoding with schema encoding '${schema?.encoding}'`);
    }
    const descriptorSet = descriptor.FileDescriptorSet.decode(schema.data);
    for (const file of descriptorSet.file) {
      if (file.package === "google.protobuf") {
        for (const message of file.messageType ?? []) {
          if (message.name === "Timestamp" || message.name === "Duration") {
            for (const field of message.field ?? []) {
              if (field.name === "seconds") field.name = "sec";
              else if (field.name === "nanos") field.name = "nsec";
            }
          }
        }
      }
    }
    const root = protobufjs.Root.fromDescriptor(descriptorSet);
    root.resolveAll();
    const type = root.lookupType(schema.name);
    const deserialize = (data) =>
      type.toObject(type.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)), {
        defaults: true,
      });
    return { deserialize, type };
  }
  throw new Error(`unsupported message encoding ${channel.messageEncoding}`);
}

/** The reference protobuf type of foxglove.<name>, from @foxglove/schemas. */
function referenceType(name) {
  const schema = foxgloveMessageSchemas[name];
  if (!schema) return undefined;
  // generateProto writes one message with its imports; parse it with stub imports resolved.
  const root = new protobufjs.Root();
  const seen = new Set();
  const add = (s) => {
    if (seen.has(s.name)) return;
    seen.add(s.name);
    for (const f of s.fields) {
      if (f.type.type === "nested" && !f.type.schema.protoEquivalent) add(f.type.schema);
    }
    const enums = s.fields.filter((f) => f.type.type === "enum").map((f) => f.type.enum);
    const text = generateProto(s, [...new Map(enums.map((e) => [e.name, e])).values()])
      .split("\n")
      .filter((l) => !l.startsWith("import "))
      .join("\n");
    protobufjs.parse(text, root, { keepCase: true });
  };
  add(schema);
  // google.protobuf.Timestamp/Duration stand-ins with Foxglove's renamed fields.
  protobufjs.parse(
    "syntax = \"proto3\"; package google.protobuf; message Timestamp { int64 sec = 1; int32 nsec = 2; } message Duration { int64 sec = 1; int32 nsec = 2; }",
    root,
    { keepCase: true },
  );
  root.resolveAll();
  return root.lookupType(`foxglove.${name}`);
}

/** Field-by-field: every field Foxglove's definition has, with the same number and type. */
function compareTypes(actual, expected, where, problems) {
  for (const f of expected.fieldsArray) {
    const a = actual.fields[f.name];
    if (!a) {
      problems.push(`${where}.${f.name} missing`);
      continue;
    }
    if (a.id !== f.id) problems.push(`${where}.${f.name} is field ${a.id}, Foxglove's is ${f.id}`);
    if (a.repeated !== f.repeated) problems.push(`${where}.${f.name} repeated=${a.repeated}, expected ${f.repeated}`);
    const aType = a.resolvedType ? a.resolvedType.fullName.replace(/^\./, "") : a.type;
    const eType = f.resolvedType ? f.resolvedType.fullName.replace(/^\./, "") : f.type;
    if (aType !== eType) problems.push(`${where}.${f.name} has type ${aType}, Foxglove's is ${eType}`);
    else if (f.resolvedType instanceof protobufjs.Type && a.resolvedType instanceof protobufjs.Type) {
      if (!eType.startsWith("google.protobuf")) compareTypes(a.resolvedType, f.resolvedType, `${where}.${f.name}`, problems);
    }
  }
}

const nsOf = (t) => BigInt(t.sec) * 1000000000n + BigInt(t.nsec);
const num = (v) => (typeof v === "object" && v !== null && "toNumber" in v ? v.toNumber() : Number(v));
const quatNorm = (q) => Math.hypot(q.x, q.y, q.z, q.w);
const finite = (...xs) => xs.every((x) => Number.isFinite(x));

function percentile(sorted, p) {
  if (sorted.length === 0) return NaN;
  return sorted[Math.min(sorted.length - 1, Math.floor(p * sorted.length))];
}

/** Panel configs from a layout, keyed by panel id. */
function panels(layout) {
  return Object.entries(layout.configById ?? {});
}

async function main(argv) {
  const args = argv.slice(2);
  const file = args.find((a) => !a.startsWith("--") && args[args.indexOf(a) - 1] !== "--layout");
  const layoutPath = args.includes("--layout") ? args[args.indexOf("--layout") + 1] : DEFAULT_LAYOUT;
  const asJson = args.includes("--json");
  if (!file) {
    process.stderr.write("usage: node check.js FILE.mcap [--layout LAYOUT.json] [--json]\n");
    return 2;
  }
  const report = new Report();
  const layout = JSON.parse(fs.readFileSync(layoutPath, "utf8"));
  await zstd.isLoaded;
  await lz4.isLoaded;

  const fd = fs.openSync(file, "r");
  const size = fs.fstatSync(fd).size;
  let reader;
  try {
    reader = await McapIndexedReader.Initialize({
      readable: fileReadable(fd, size),
      decompressHandlers: {
        zstd: (buffer, decompressedSize) => zstd.decompress(buffer, Number(decompressedSize)),
        lz4: (buffer, decompressedSize) => lz4(buffer, Number(decompressedSize)),
      },
    });
  } catch (e) {
    report.check(false, "indexed reader opens the file", e.message);
    return finish(report, asJson);
  }
  report.check(true, "indexed reader opens the file", `${reader.chunkIndexes.length} chunks`);

  // --- The timeline: Foxglove takes the file's start/end from the chunk indexes (min/max of
  // messageStartTime/messageEndTime, McapIndexedIterableSource.initialize), not from the
  // statistics. A chunk holding no message has times (0, 0) and would start the timeline at 1970.
  let chunkStart, chunkEnd;
  for (const c of reader.chunkIndexes) {
    if (chunkStart === undefined || c.messageStartTime < chunkStart) chunkStart = c.messageStartTime;
    if (chunkEnd === undefined || c.messageEndTime > chunkEnd) chunkEnd = c.messageEndTime;
  }
  const stats = reader.statistics;
  const empty = reader.chunkIndexes.filter((c) => c.messageIndexLength === 0n);
  report.check(
    empty.length === 0,
    "every chunk holds messages (older @mcap/core, as in Foxglove Studio 1.x and Lichtblick builds before 2025, throws on chunks without message indexes)",
    empty.length ? `${empty.length} chunk(s) without messages, first at offset ${empty[0].chunkStartOffset}` : "",
  );
  if (stats) {
    report.check(
      chunkStart === stats.messageStartTime && chunkEnd === stats.messageEndTime,
      "timeline from the chunk indexes equals the messages' time range",
      `chunks ${chunkStart}..${chunkEnd} ns, messages ${stats.messageStartTime}..${stats.messageEndTime} ns`,
    );
  }

  // --- Every channel decodes with Foxglove's parseChannel; foxglove.* schemas match Foxglove's.
  const channels = new Map(); // id -> { channel, schema, parsed }
  const byTopic = new Map(); // topic -> { schemaName, id }
  for (const channel of reader.channelsById.values()) {
    const schema = reader.schemasById.get(channel.schemaId);
    let parsed;
    try {
      parsed = parseChannel(channel, schema);
    } catch (e) {
      report.check(false, `${channel.topic}: Foxglove's parseChannel accepts the schema`, e.message);
      continue;
    }
    channels.set(channel.id, { channel, schema, parsed });
    byTopic.set(channel.topic, { schemaName: schema?.name, id: channel.id });
    if (parsed.type && schema.name.startsWith("foxglove.")) {
      const ref = referenceType(schema.name.slice("foxglove.".length));
      const problems = [];
      if (!ref) problems.push(`no foxglove schema named ${schema.name}`);
      else compareTypes(parsed.type, ref, schema.name, problems);
      report.check(problems.length === 0, `${channel.topic}: ${schema.name} matches @foxglove/schemas`, problems.join("; "));
    }
  }

  // --- Read every message once, decoded.
  const messages = new Map(); // topic -> [{ logTime, msg }]
  let decodeErrors = 0;
  let firstDecodeError = "";
  let count = 0;
  for await (const m of reader.readMessages()) {
    const info = channels.get(m.channelId);
    if (!info) continue;
    let msg;
    try {
      msg = info.parsed.deserialize(m.data);
    } catch (e) {
      decodeErrors += 1;
      firstDecodeError ||= `${info.channel.topic}: ${e.message}`;
      continue;
    }
    count += 1;
    const list = messages.get(info.channel.topic) ?? [];
    list.push({ logTime: m.logTime, msg });
    messages.set(info.channel.topic, list);
  }
  fs.closeSync(fd);
  report.check(decodeErrors === 0, "every message decodes", decodeErrors ? `${decodeErrors} failed; ${firstDecodeError}` : `${count} messages`);
  if (stats) {
    report.check(BigInt(count) === stats.messageCount, "message count equals the statistics", `${count} read, ${stats.messageCount} in statistics`);
  }

  // --- Layout panels: topics exist with a schema the panel takes.
  const imagePanels = panels(layout).filter(([id]) => id.startsWith("Image!"));
  const topicSchema = (t) => byTopic.get(t)?.schemaName;
  const requireTopic = (panel, topic, accepted, what) =>
    report.check(
      accepted.has(topicSchema(topic)),
      `${panel}: ${what} ${topic} is in the file with a schema the panel takes`,
      `schema ${topicSchema(topic) ?? "(topic absent)"}`,
    );
  for (const [id, config] of imagePanels) {
    const mode = config.imageMode ?? {};
    requireTopic(id, mode.imageTopic, IMAGE_SCHEMAS, "imageTopic");
    if (mode.calibrationTopic) requireTopic(id, mode.calibrationTopic, CALIBRATION_SCHEMAS, "calibrationTopic");
    for (const topic of Object.keys(mode.annotations ?? {})) requireTopic(id, topic, ANNOTATION_SCHEMAS, "annotation topic");
  }

  // --- Images: sizes, encodings, steps; calibration matches; mask and annotations line up.
  const imageTopicOf = (panelId) => layout.configById[panelId]?.imageMode?.imageTopic;
  const colourPanel = imagePanels.find(([, c]) => Object.keys(c.imageMode?.annotations ?? {}).length > 0);
  const colourTopic = colourPanel ? colourPanel[1].imageMode.imageTopic : "/camera/rgb/image";
  const colourByStamp = new Map();
  for (const { msg } of messages.get(colourTopic) ?? []) colourByStamp.set(nsOf(msg.timestamp), msg);
  const compressedSize = (msg) => {
    // PNG IHDR or JPEG SOF size, enough to place annotations on compressed colour.
    const d = Buffer.from(msg.data);
    if (d.length > 24 && d.readUInt32BE(0) === 0x89504e47) return { width: d.readUInt32BE(16), height: d.readUInt32BE(20) };
    for (let i = 2; i + 9 < d.length; ) {
      if (d[i] !== 0xff) break;
      const marker = d[i + 1];
      const len = d.readUInt16BE(i + 2);
      if (marker >= 0xc0 && marker <= 0xcf && marker !== 0xc4 && marker !== 0xc8 && marker !== 0xcc) {
        return { width: d.readUInt16BE(i + 7), height: d.readUInt16BE(i + 5) };
      }
      i += 2 + len;
    }
    return undefined;
  };
  const sizeOf = (msg) => ("encoding" in msg && "step" in msg ? { width: msg.width, height: msg.height } : compressedSize(msg));

  const checkRaw = (topic, expectEncoding) => {
    const list = messages.get(topic) ?? [];
    if (topicSchema(topic) !== "foxglove.RawImage") return;
    const bad = [];
    for (const { logTime, msg } of list) {
      const bpp = RAW_ENCODING_BYTES[msg.encoding];
      if (bpp === undefined) bad.push(`${logTime}: encoding ${msg.encoding} not decoded by Foxglove`);
      else if (msg.step < msg.width * bpp) bad.push(`${logTime}: step ${msg.step} < width ${msg.width} x ${bpp}`);
      else if (msg.data.length < msg.step * msg.height) bad.push(`${logTime}: ${msg.data.length} bytes < step x height`);
      if (expectEncoding && msg.encoding !== expectEncoding) bad.push(`${logTime}: encoding ${msg.encoding}, expected ${expectEncoding}`);
      if (bad.length > 3) break;
    }
    report.check(list.length > 0 && bad.length === 0, `${topic}: RawImage encoding/step/size decodable`, bad.join("; ") || `${list.length} images, ${list[0]?.msg.encoding}`);
  };
  const rawTopics = new Set(imagePanels.map(([, c]) => c.imageMode.imageTopic));
  for (const topic of rawTopics) checkRaw(topic, topic === "/occmask/mask" ? "mono8" : undefined);
  if (!rawTopics.has("/occmask/mask")) checkRaw("/occmask/mask", "mono8");

  for (const [id, config] of imagePanels) {
    const mode = config.imageMode ?? {};
    if (!mode.calibrationTopic) continue;
    const images = messages.get(mode.imageTopic) ?? [];
    const infos = messages.get(mode.calibrationTopic) ?? [];
    const size0 = images.length ? sizeOf(images[0].msg) : undefined;
    const bad = infos.filter(({ msg }) => !size0 || msg.width !== size0.width || msg.height !== size0.height || msg.frame_id !== images[0].msg.frame_id || !(msg.K[0] > 0 && msg.K[4] > 0));
    report.check(infos.length > 0 && bad.length === 0, `${id}: calibration matches its image (size, frame_id, K)`, bad.length ? `${bad.length} mismatching, e.g. ${JSON.stringify({ w: bad[0].msg.width, h: bad[0].msg.height, frame: bad[0].msg.frame_id })}` : `${infos.length} calibrations`);
  }

  const masks = messages.get("/occmask/mask") ?? [];
  {
    const bad = [];
    for (const { msg } of masks) {
      const c = colourByStamp.get(nsOf(msg.timestamp));
      const cs = c && sizeOf(c);
      if (!c) bad.push(`mask at ${nsOf(msg.timestamp)} ns has no colour image with that stamp`);
      else if (!cs || cs.width !== msg.width || cs.height !== msg.height) bad.push(`mask ${msg.width}x${msg.height} vs colour ${cs?.width}x${cs?.height}`);
      else if (c.frame_id !== msg.frame_id) bad.push(`mask frame ${msg.frame_id} vs colour ${c.frame_id}`);
      else if (msg.data.some((v) => v !== 0 && v !== 255)) bad.push(`mask at ${nsOf(msg.timestamp)} has values other than 0/255`);
      if (bad.length > 3) break;
    }
    report.check(masks.length > 0 && bad.length === 0, "/occmask/mask: one per colour image, same stamp, size and frame, values 0/255", bad.join("; ") || `${masks.length} masks`);
  }

  const annotations = messages.get("/occmask/mask_annotations") ?? [];
  {
    const bad = [];
    let polygons = 0;
    let framesWithMoving = 0;
    const maskByStamp = new Map(masks.map(({ msg }) => [nsOf(msg.timestamp), msg]));
    for (const { msg } of annotations) {
      const stamp = nsOf(msg.timestamp);
      const c = colourByStamp.get(stamp);
      const cs = c && sizeOf(c);
      if (!c) {
        bad.push(`annotations at ${stamp} ns: no colour image with that stamp (synchronize would never show them)`);
        continue;
      }
      const mask = maskByStamp.get(stamp);
      const moving = mask ? mask.data.some((v) => v === 255) : false;
      if (moving) framesWithMoving += 1;
      // occmask outlines regions of at least MIN_OUTLINE_AREA_PX (contour::ContourOptions):
      // a mask of smaller regions only has none.
      const outlined = moving && largestRegion(mask) >= MIN_OUTLINE_AREA_PX;
      if (!moving && msg.points.length > 0) bad.push(`${stamp}: mask has no moving pixels but ${msg.points.length} outlines`);
      if (outlined && msg.points.length === 0) bad.push(`${stamp}: mask has a region of at least ${MIN_OUTLINE_AREA_PX} px but no outline`);
      for (const p of msg.points) {
        polygons += 1;
        if (nsOf(p.timestamp) !== stamp) bad.push(`${stamp}: outline stamp ${nsOf(p.timestamp)} differs from the image's`);
        if (p.type !== POINTS_TYPE.LINE_LOOP) bad.push(`${stamp}: outline type ${p.type}, expected LINE_LOOP`);
        if (p.points.length < 3) bad.push(`${stamp}: outline with ${p.points.length} points`);
        if (!(p.thickness > 0)) bad.push(`${stamp}: thickness ${p.thickness}`);
        const outline = p.outline_color;
        const fill = p.fill_color;
        if (!outline || !(outline.a > 0)) bad.push(`${stamp}: invisible outline colour`);
        if (!fill || !(fill.a > 0 && fill.a < 1)) bad.push(`${stamp}: fill alpha ${fill?.a}, expected translucent (0 < a < 1)`);
        for (const q of p.points) {
          if (!(finite(q.x, q.y) && q.x >= 0 && q.y >= 0 && q.x <= cs.width && q.y <= cs.height)) {
            bad.push(`${stamp}: point (${q.x}, ${q.y}) outside the ${cs.width}x${cs.height} image`);
            break;
          }
        }
        if (bad.length > 3) break;
      }
      if (bad.length > 3) break;
    }
    report.check(
      annotations.length > 0 && annotations.length === (messages.get(colourTopic) ?? []).length && bad.length === 0,
      "/occmask/mask_annotations: one per colour image at its stamp, translucent LINE_LOOP outlines inside the image, present when the mask has a region of 16 px or more, absent when it has no moving pixels",
      bad.join("; ") || `${annotations.length} messages, ${polygons} outlines, ${framesWithMoving} frames with moving pixels`,
    );
  }

  // --- Synchronized annotations: Foxglove's Image panel (MessageHandler in image mode, and the
  // older ImageViewPanel) files annotations by each annotation's own stamp, so a message with no
  // annotation adds nothing and an image whose stamp gets none is never shown with synchronize
  // on: the panel stays on the last frame that had outlines. Synchronize therefore needs at least
  // one annotation per image.
  for (const [id, config] of imagePanels) {
    const mode = config.imageMode ?? {};
    if (mode.synchronize !== true) continue;
    for (const topic of Object.keys(mode.annotations ?? {})) {
      const emptyCount = (messages.get(topic) ?? []).filter(({ msg }) => (msg.points?.length ?? 0) + (msg.circles?.length ?? 0) + (msg.texts?.length ?? 0) === 0).length;
      report.check(emptyCount === 0, `${id}: synchronize is on, so every ${topic} message needs an annotation (an empty one hides its image)`, `${emptyCount} empty messages`);
    }
  }

  // --- Depth colour map range vs the depth values.
  for (const [id, config] of imagePanels) {
    const mode = config.imageMode ?? {};
    if (mode.colorMode !== "colormap") continue;
    const list = messages.get(mode.imageTopic) ?? [];
    const values = [];
    for (let i = 0; i < list.length; i += Math.max(1, Math.floor(list.length / 10))) {
      const msg = list[i].msg;
      if (msg.encoding !== "16UC1" && msg.encoding !== "mono16") continue;
      const d = Buffer.from(msg.data);
      for (let y = 0; y < msg.height; y += 4) {
        for (let x = 0; x < msg.width; x += 4) {
          const v = msg.is_bigendian ? d.readUInt16BE(y * msg.step + 2 * x) : d.readUInt16LE(y * msg.step + 2 * x);
          if (v > 0) values.push(v);
        }
      }
    }
    values.sort((a, b) => a - b);
    const [p1, p99] = [percentile(values, 0.01), percentile(values, 0.99)];
    const min = mode.minValue ?? 0;
    const max = mode.maxValue ?? 65535;
    report.check(
      list.length > 0 && values.length > 0 && p1 >= min && p99 <= max && p99 - min >= MIN_RANGE_USE * (max - min),
      `${id}: colour-map range ${min}..${max} covers the depth (1st..99th percentile of valid pixels) and uses at least ${MIN_RANGE_USE * 100}% of it`,
      `depth ${p1}..${p99} (${list[0]?.msg.encoding}), ${values.length} samples`,
    );
  }

  // --- Transforms: a tree rooted at world reaching the estimated and ground-truth frames.
  const tfTopics = [...byTopic.entries()].filter(([, v]) => v.schemaName === "foxglove.FrameTransform").map(([t]) => t);
  const parentOf = new Map();
  const tfBad = [];
  for (const topic of tfTopics) {
    for (const { msg } of messages.get(topic) ?? []) {
      const prev = parentOf.get(msg.child_frame_id);
      if (prev !== undefined && prev !== msg.parent_frame_id) tfBad.push(`${msg.child_frame_id} has parents ${prev} and ${msg.parent_frame_id}`);
      parentOf.set(msg.child_frame_id, msg.parent_frame_id);
      const t = msg.translation;
      const r = msg.rotation;
      if (!finite(t.x, t.y, t.z) || Math.abs(quatNorm(r) - 1) > QUAT_NORM_TOL) tfBad.push(`${topic} ${msg.child_frame_id}: non-finite translation or non-unit rotation`);
      if (tfBad.length > 3) break;
    }
  }
  const rootOf = (frame) => {
    const seen = new Set();
    while (parentOf.has(frame)) {
      if (seen.has(frame)) return undefined;
      seen.add(frame);
      frame = parentOf.get(frame);
    }
    return frame;
  };
  const scene = panels(layout).find(([id]) => id.startsWith("3D!"));
  const sceneFrames = scene ? Object.keys(scene[1].transforms ?? {}).map((k) => k.replace(/^frame:/, "")) : [];
  const inFile = sceneFrames.filter((f) => f === "world" || parentOf.has(f));
  report.check(
    tfBad.length === 0 && parentOf.has("camera_estimated") && inFile.every((f) => rootOf(f) === "world"),
    "FrameTransforms form a tree rooted at world that reaches camera_estimated and the layout's frames present in the file",
    tfBad.join("; ") || [...parentOf.entries()].map(([c, p]) => `${p} -> ${c}`).join(", ") + (inFile.length < sceneFrames.length ? `; not in this file: ${sceneFrames.filter((f) => !inFile.includes(f)).join(", ")}` : ""),
  );

  // --- Poses and path: frame ids the 3D panel can place, unit quaternions; path ends at the
  // odometry pose of its stamp.
  const knownFrame = (f) => f === "world" || parentOf.has(f);
  for (const topic of ["/occmask/odometry", "/groundtruth/pose"]) {
    const list = messages.get(topic) ?? [];
    if (topic === "/groundtruth/pose" && list.length === 0) continue;
    const bad = list.filter(({ msg }) => !knownFrame(msg.frame_id) || Math.abs(quatNorm(msg.pose.orientation) - 1) > QUAT_NORM_TOL || !finite(msg.pose.position.x, msg.pose.position.y, msg.pose.position.z));
    report.check(list.length > 0 && bad.length === 0, `${topic}: PoseInFrame in a frame of the transform tree, unit quaternions`, bad.length ? `${bad.length} bad, e.g. frame ${bad[0].msg.frame_id}` : `${list.length} poses in ${list[0].msg.frame_id}`);
  }
  {
    const paths = messages.get("/occmask/path") ?? [];
    const odomByStamp = new Map((messages.get("/occmask/odometry") ?? []).map(({ msg }) => [nsOf(msg.timestamp), msg]));
    const bad = [];
    let prevLen = 0;
    for (const { msg } of paths) {
      if (!knownFrame(msg.frame_id)) bad.push(`path frame ${msg.frame_id} not in the transform tree`);
      if (msg.poses.length < 1) bad.push("empty path");
      const last = msg.poses[msg.poses.length - 1];
      const odom = odomByStamp.get(nsOf(msg.timestamp));
      if (!odom) bad.push(`path at ${nsOf(msg.timestamp)} ns has no odometry pose at that stamp`);
      else if (last && Math.hypot(last.position.x - odom.pose.position.x, last.position.y - odom.pose.position.y, last.position.z - odom.pose.position.z) > 1e-9) bad.push(`path at ${nsOf(msg.timestamp)} does not end at the odometry pose`);
      if (msg.poses.length < prevLen && msg.poses.length < 2) bad.push("path shrank to a point");
      prevLen = msg.poses.length;
    }
    report.check(paths.length > 0 && bad.length === 0, "/occmask/path: PosesInFrame in world ending at the current odometry pose", bad.slice(0, 3).join("; ") || `${paths.length} paths, last with ${prevLen} poses`);
  }
  {
    // The anchor channel's path (only when the run was anchored): in a known frame, ending at
    // the anchor pose channel's pose of a frame no later than the path's stamp.
    const anchorPaths = messages.get("/occmask/anchor_path") ?? [];
    if (anchorPaths.length > 0) {
      const bad = anchorPaths
        .filter(({ msg }) => !knownFrame(msg.frame_id) || msg.poses.length < 1 || msg.poses.some((p) => Math.abs(quatNorm(p.orientation) - 1) > QUAT_NORM_TOL || !finite(p.position.x, p.position.y, p.position.z)))
        .map(({ msg }) => `anchor path at ${nsOf(msg.timestamp)} ns in ${msg.frame_id} with ${msg.poses.length} poses`);
      report.check(bad.length === 0, "/occmask/anchor_path: PosesInFrame in a frame of the transform tree, unit quaternions", bad.slice(0, 3).join("; ") || `${anchorPaths.length} paths`);
    }
  }

  // --- Point clouds (opt-in): one per colour image at its stamp, in a frame of the transform
  // tree, x/y/z float32 and red/green/blue/alpha uint8 inside the stride, finite points in front
  // of the camera.
  if (byTopic.has("/occmask/points")) {
    const clouds = messages.get("/occmask/points") ?? [];
    const maskStamps = new Set((messages.get("/occmask/mask") ?? []).map(({ msg }) => nsOf(msg.timestamp)));
    const bad = [];
    let points = 0;
    for (const { msg } of clouds) {
      const fields = new Map((msg.fields ?? []).map((f) => [f.name, f]));
      const want = { x: NUMERIC.FLOAT32, y: NUMERIC.FLOAT32, z: NUMERIC.FLOAT32, red: NUMERIC.UINT8, green: NUMERIC.UINT8, blue: NUMERIC.UINT8, alpha: NUMERIC.UINT8 };
      for (const [name, type] of Object.entries(want)) {
        const f = fields.get(name);
        const size = type === NUMERIC.FLOAT32 ? 4 : 1;
        if (!f || f.type !== type || f.offset + size > msg.point_stride) bad.push(`field ${name}: ${JSON.stringify(f)}`);
      }
      if (!knownFrame(msg.frame_id)) bad.push(`frame ${msg.frame_id} not in the transform tree`);
      if (!maskStamps.has(nsOf(msg.timestamp))) bad.push(`cloud at ${nsOf(msg.timestamp)} ns has no mask at that stamp`);
      const data = msg.data ?? new Uint8Array();
      if (msg.point_stride <= 0 || data.length % msg.point_stride !== 0) bad.push(`${data.length} bytes, stride ${msg.point_stride}`);
      const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
      const [fx, fy, fz] = ["x", "y", "z"].map((n) => fields.get(n)?.offset ?? 0);
      for (let o = 0; msg.point_stride > 0 && o + msg.point_stride <= data.length; o += msg.point_stride) {
        const [x, y, z] = [fx, fy, fz].map((f) => view.getFloat32(o + f, true));
        if (!finite(x, y, z) || !(z > 0)) {
          bad.push(`point (${x}, ${y}, ${z})`);
          break;
        }
        points += 1;
      }
      if (bad.length > 3) break;
    }
    report.check(
      clouds.length > 0 && clouds.length === maskStamps.size && bad.length === 0,
      "/occmask/points: PointCloud per colour image at its stamp, in the transform tree, xyz float32 + rgba uint8 fields, finite points in front of the camera",
      bad.slice(0, 3).join("; ") || `${clouds.length} clouds, ${points} points, frame ${clouds[0]?.msg.frame_id}`,
    );
    // The 3D panel's colours. On a topic's first message Foxglove fills in a missing colorField
    // and with it replaces the colour mode (Studio 1.48: a colour map of the first field, x, for
    // this cloud), so a colour mode holds only beside a colorField of the cloud; "rgba-fields"
    // reads the red, green, blue and alpha fields.
    const pointsConfig = scene?.[1].topics?.["/occmask/points"];
    if (pointsConfig?.colorMode !== undefined) {
      const names = new Set((clouds[0]?.msg.fields ?? []).map((f) => f.name));
      const { colorMode, colorField } = pointsConfig;
      const rgbaFields = ["red", "green", "blue", "alpha"].every((n) => names.has(n));
      report.check(
        names.has(colorField) && (colorMode !== "rgba-fields" || rgbaFields),
        `${scene[0]}: /occmask/points colour mode ${colorMode} beside a colorField of the cloud (without one Foxglove picks its own mode)`,
        `colorField ${colorField}, fields ${[...names].join(", ")}`,
      );
    }
  }

  // --- 3D panel and plot topics.
  if (scene) {
    const [id, config] = scene;
    for (const topic of Object.keys(config.topics ?? {})) {
      if (OPTIONAL_TOPICS.has(topic) && !byTopic.has(topic)) continue;
      requireTopic(id, topic, THREE_D_TOPIC_SCHEMAS, "topic");
    }
    report.check(knownFrame(config.followTf ?? "world"), `${id}: display frame ${config.followTf} is in the transform tree`);
    for (const layer of Object.values(config.layers ?? {})) {
      if (layer.frameId) report.check(knownFrame(layer.frameId), `${id}: layer ${layer.layerId} frame ${layer.frameId} is in the transform tree`);
    }
  }
  for (const [id, config] of panels(layout).filter(([pid]) => pid.startsWith("Plot!"))) {
    for (const p of config.paths ?? []) {
      const [topic, ...fieldPath] = p.value.split(".");
      const list = messages.get(topic) ?? [];
      const values = list.map(({ msg }) => fieldPath.reduce((o, k) => (o == undefined ? undefined : o[k]), msg));
      report.check(
        list.length > 0 && values.every((v) => typeof v === "number" && Number.isFinite(v)),
        `${id}: ${p.value} is a finite number in every message`,
        `${list.length} messages${values.length ? `, first ${values[0]}` : ""}`,
      );
    }
  }
  return finish(report, asJson);
}

function finish(report, asJson) {
  if (asJson) {
    process.stdout.write(JSON.stringify({ ok: report.failed.length === 0, results: report.results }, null, 1) + "\n");
  } else {
    for (const r of report.results) {
      process.stdout.write(`${r.ok ? "ok  " : "FAIL"} ${r.name}${r.detail ? `: ${r.detail}` : ""}\n`);
    }
    process.stdout.write(`${report.results.length - report.failed.length}/${report.results.length} checks passed\n`);
  }
  return report.failed.length === 0 ? 0 : 1;
}

main(process.argv).then(
  (code) => process.exit(code),
  (e) => {
    process.stderr.write(`error: ${e.stack ?? e}\n`);
    process.exit(1);
  },
);
