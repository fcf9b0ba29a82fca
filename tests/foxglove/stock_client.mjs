// The stock Foxglove WebSocket client: `@foxglove/ws-protocol` 0.8.0's FoxgloveClient (what
// Foxglove Studio 1.x and the tools built on it use) over the `ws` package, offering the
// subprotocol it offers (`foxglove.websocket.v1`) or, with --subprotocol, another name.
//
// Usage: node stock_client.mjs --url ws://HOST:PORT --out FILE [--seconds S]
//            [--subprotocol NAME] [--publish-order JSON] [--origin ORIGIN]
//
// It subscribes to every advertised channel as soon as it is advertised, counts messages and
// bytes per topic for --seconds, notes when the first message of each topic came (ms after its
// subscription), publishes each --publish-order on an /orders channel it advertises (json
// encoding) one second after subscribing, and writes --out as JSON:
//   {"subprotocol": "...", "counts": {topic: n}, "bytes": {topic: n}, "first_ms": {topic: ms},
//    "seconds": S, "published": n, "statuses": [...], "schemas": {topic: schemaName}}
// --origin sends that Origin header, as a browser page of that site would.
// Exit 0 once written; 1 (with the reason on stderr) if it could not connect.
import { writeFileSync } from "node:fs";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

function args(argv) {
  const out = { seconds: 5, orders: [], subprotocol: FoxgloveClient.SUPPORTED_SUBPROTOCOL };
  for (let i = 2; i < argv.length; i += 2) {
    const [flag, value] = [argv[i], argv[i + 1]];
    if (flag === "--url") out.url = value;
    else if (flag === "--out") out.out = value;
    else if (flag === "--seconds") out.seconds = Number(value);
    else if (flag === "--subprotocol") out.subprotocol = value;
    else if (flag === "--publish-order") out.orders.push(value);
    else if (flag === "--origin") out.origin = value;
    else {
      console.error(`stock_client: unknown flag ${flag}`);
      process.exit(2);
    }
  }
  return out;
}

const opts = args(process.argv);
const ws = new WebSocket(opts.url, [opts.subprotocol], opts.origin ? { origin: opts.origin } : {});
const client = new FoxgloveClient({ ws });
const result = {
  subprotocol: null, counts: {}, bytes: {}, first_ms: {}, seconds: opts.seconds,
  published: 0, statuses: [], schemas: {}, advertised: [],
};
const topics = new Map(); // subscription id -> [topic, subscribed at]
let started = null;

client.on("error", (e) => {
  console.error(`stock_client: ${e?.message ?? e}`);
  process.exit(1);
});
client.on("open", () => {
  result.subprotocol = ws.protocol;
});
client.on("status", (s) => result.statuses.push(s.message));
client.on("advertise", (channels) => {
  for (const c of channels) {
    result.advertised.push(c.topic);
    result.schemas[c.topic] = c.schemaName;
    const id = client.subscribe(c.id);
    topics.set(id, [c.topic, Date.now()]);
    result.counts[c.topic] ??= 0;
    result.bytes[c.topic] ??= 0;
  }
  if (started === null) {
    started = Date.now();
    setTimeout(publish, 1000);
    setTimeout(finish, opts.seconds * 1000);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const [topic, since] = topics.get(subscriptionId) ?? ["?", Date.now()];
  result.counts[topic] = (result.counts[topic] ?? 0) + 1;
  result.bytes[topic] = (result.bytes[topic] ?? 0) + data.byteLength;
  if (!(topic in result.first_ms)) result.first_ms[topic] = Date.now() - since;
});

function publish() {
  if (opts.orders.length === 0) return;
  const channel = client.advertise({ topic: "/orders", encoding: "json", schemaName: "order" });
  const encoder = new TextEncoder();
  for (const order of opts.orders) {
    client.sendMessage(channel, encoder.encode(order));
    result.published += 1;
  }
}

function finish() {
  writeFileSync(opts.out, JSON.stringify(result));
  client.close();
  process.exit(0);
}

setTimeout(() => {
  console.error("stock_client: no channels advertised within 20 s");
  process.exit(1);
}, 20000 + opts.seconds * 1000);
