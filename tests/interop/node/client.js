// A viewer of semloc's live view built on Foxglove's own client library (@foxglove/ws-protocol),
// for tests/interop/test_foxglove_client.py.
//
//   node client.js URL SUBPROTOCOL TOPIC...
//
// Connects offering only SUBPROTOCOL, subscribes to every advertised channel, decodes each
// message with the schema its channel advertises (protobuf: a FileDescriptorSet, by protobufjs)
// and prints one JSON line per event: {"open": subprotocol}, {"channels": [...]}, then
// {"topic", "schemaName", "message"} per message.  Exits 0 once every TOPIC has had a message;
// exits 1 on an error or after WAIT_MS without them.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const WAIT_MS = 20000;
const [url, subprotocol, ...wanted] = process.argv.slice(2);
const ws = new WebSocket(url, [subprotocol]);
const client = new FoxgloveClient({ ws });
const decoders = new Map(); // subscription id -> { channel, type }
const seen = new Set();

function print(value) {
  process.stdout.write(JSON.stringify(value) + "\n");
}

function fail(why) {
  process.stderr.write(why + "\n");
  process.exit(1);
}

function decoder(channel) {
  if (channel.encoding !== "protobuf" || channel.schemaEncoding !== "protobuf") {
    fail(`${channel.topic}: not protobuf (${channel.encoding}, ${channel.schemaEncoding})`);
  }
  const files = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
  return protobuf.Root.fromDescriptor(files).lookupType(channel.schemaName);
}

setTimeout(() => fail(`no message on ${wanted.filter((t) => !seen.has(t)).join(", ")}`), WAIT_MS);
client.on("error", (error) => fail(`error: ${error.message ?? error}`));
client.on("close", (event) => fail(`closed: ${event.code} ${event.reason}`));
client.on("open", () => print({ open: ws.protocol }));
client.on("advertise", (channels) => {
  print({ channels });
  for (const channel of channels) {
    const id = client.subscribe(channel.id);
    decoders.set(id, { channel, type: decoder(channel) });
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const { channel, type } = decoders.get(subscriptionId);
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  const message = type.toObject(type.decode(bytes), {
    longs: Number,
    enums: String,
    defaults: true,
  });
  print({ topic: channel.topic, schemaName: channel.schemaName, message });
  seen.add(channel.topic);
  if (wanted.every((topic) => seen.has(topic))) {
    process.exit(0);
  }
});
