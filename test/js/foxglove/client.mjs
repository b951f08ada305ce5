// Foxglove's own WebSocket client (@foxglove/ws-protocol) with its ROS 2 decoder
// (@foxglove/rosmsg + @foxglove/rosmsg2-serialization): connects to a fence_sorter Foxglove
// server, subscribes to the named topics and writes every message it decodes as one JSON line
// {topic, log_time, schema, message} to OUT. Used by test/ros/test_foxglove_live.py.
//
//   node client.mjs URL OUT TIMEOUT_S [--stall] [--subprotocol=NAME] TOPIC...
//
// It retries the connection until the server is up (within TIMEOUT_S), prints
// "subscribed TOPIC" for each subscription and "closed N" when the server goes away (the end
// of the run), then exits 0. --stall: once subscribed to every topic, stop reading the socket
// (prints "stalled"): a slow client whose outbox on the server fills up; SIGUSR2 makes it read
// again (prints "resumed"), so what the server did not drop arrives. The socket is opened here
// and handed to FoxgloveClient, with the subprotocol "foxglove.sdk.v1" (foxglove-sdk's name)
// unless --subprotocol=NAME says another; --subprotocol=client: the client's own constant
// FoxgloveClient.SUPPORTED_SUBPROTOCOL ("foxglove.websocket.v1").
import { createWriteStream } from "node:fs";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

// CommonJS packages: their exports come as one default object
const { parse } = rosmsg;
const { MessageReader } = serialization;
const { FoxgloveClient } = wsProtocol;

const [url, outPath, timeoutText, ...rest] = process.argv.slice(2);
let stall = false;
let SUBPROTOCOL = "foxglove.sdk.v1";
while (rest.length > 0 && rest[0].startsWith("--")) {
  const option = rest.shift();
  if (option === "--stall") stall = true;
  else if (option.startsWith("--subprotocol=")) SUBPROTOCOL = option.slice("--subprotocol=".length);
}
if (SUBPROTOCOL === "client") SUBPROTOCOL = FoxgloveClient.SUPPORTED_SUBPROTOCOL;
const topics = rest;
if (!url || !outPath || !timeoutText || topics.length === 0) {
  console.error("usage: node client.mjs URL OUT TIMEOUT_S TOPIC...");
  process.exit(2);
}
const deadline = Date.now() + 1000 * Number(timeoutText);
const out = createWriteStream(outPath);

// BigInt (uint64, int64) as decimal strings, typed arrays as plain arrays
function plain(_key, value) {
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value, (v) => (typeof v === "bigint" ? v.toString() : v));
  return value;
}

let stalledSocket = null;
let keepAlive = null; // a paused socket does not keep Node's event loop alive: a timer does
process.on("SIGUSR2", () => {
  if (stalledSocket === null) return;
  stalledSocket.resume();
  stalledSocket = null;
  clearInterval(keepAlive);
  console.log("resumed");
});

function connect() {
  const ws = new WebSocket(url, [SUBPROTOCOL]);
  ws.binaryType = "arraybuffer";
  let opened = false;
  ws.on("open", () => {
    opened = true;
    console.log(`open ${ws.protocol}`);
  });
  ws.on("error", () => {
    if (!opened) {
      ws.terminate();
      if (Date.now() > deadline) {
        console.error(`no Foxglove server at ${url} within ${timeoutText} s`);
        process.exit(1);
      }
      setTimeout(connect, 100);
    }
  });
  const client = new FoxgloveClient({ ws });
  const readers = new Map(); // subscription id -> {topic, schema, reader}
  let received = 0;
  client.on("advertise", (channels) => {
    for (const channel of channels) {
      if (!topics.includes(channel.topic)) continue;
      if (channel.encoding !== "cdr" || channel.schemaEncoding !== "ros2msg") {
        console.error(`${channel.topic}: encoding ${channel.encoding}/${channel.schemaEncoding}`);
        process.exit(1);
      }
      const reader = new MessageReader(parse(channel.schema, { ros2: true }));
      const id = client.subscribe(channel.id);
      readers.set(id, { topic: channel.topic, schema: channel.schemaName, reader });
      console.log(`subscribed ${channel.topic}`);
    }
    if (stall && readers.size === topics.length) {
      ws._socket.pause(); // nothing more is read: the server's outbox for this client fills
      stalledSocket = ws._socket;
      keepAlive = setInterval(() => {}, 1000);
      console.log("stalled");
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const entry = readers.get(subscriptionId);
    if (!entry) return;
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    const message = entry.reader.readMessage(bytes);
    received += 1;
    out.write(
      JSON.stringify(
        { topic: entry.topic, log_time: timestamp.toString(), schema: entry.schema, message },
        plain,
      ) + "\n",
    );
  });
  client.on("close", () => {
    if (!opened) return;
    console.log(`closed ${received}`);
    out.end(() => process.exit(0));
  });
}

process.on("SIGTERM", () => out.end(() => process.exit(0)));
connect();
