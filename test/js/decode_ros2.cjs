// Decodes ROS 2 CDR messages with Foxglove's deserializer (@foxglove/rosmsg2-serialization, the schema
// parsed by @foxglove/rosmsg), as Foxglove's MCAP player does.
// stdin: JSON lines {"topic", "schema" (ros2msg text), "data" (base64 CDR)}; the schema is sent with
// a topic's first message only. stdout: JSON lines {"topic", "message", "trailing" (bytes after the last
// field)} in the same order; int64 values as {"$int": "..."}, non-finite floats as {"$float": "..."}.
// A message that does not decode: {"topic", "error"}.
"use strict";
const readline = require("node:readline");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const readers = new Map();

function replacer(_key, value) {
  if (typeof value === "bigint") return { $int: value.toString() };
  if (typeof value === "number" && !Number.isFinite(value)) return { $float: String(value) };
  if (ArrayBuffer.isView(value)) return Array.from(value);
  return value;
}

const out = [];
readline.createInterface({ input: process.stdin, crlfDelay: Infinity }).on("line", (line) => {
  if (!line) return;
  const { topic, schema, data } = JSON.parse(line);
  if (schema !== undefined) {
    readers.set(topic, new MessageReader(parse(schema, { ros2: true })));
  }
  const reader = readers.get(topic);
  const buf = Buffer.from(data, "base64");
  try {
    const message = reader.readMessage(buf);
    out.push(JSON.stringify({ topic, message, trailing: buf.byteLength - reader.lastReadByteLength() },
      replacer));
  } catch (err) {
    out.push(JSON.stringify({ topic, error: String(err) }));
  }
  if (out.length >= 512) process.stdout.write(out.splice(0).join("\n") + "\n");
}).on("close", () => {
  if (out.length) process.stdout.write(out.join("\n") + "\n");
});
