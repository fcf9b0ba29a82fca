// The stock Foxglove WebSocket client against octo-delta's live map view
// (crates/field/src/foxglove_map.rs): `@foxglove/ws-protocol` 0.8.0's FoxgloveClient over `ws`,
// offering the stock subprotocol `foxglove.websocket.v1`.
//
// Usage: node map_client.mjs URL [--publish JSONTEXT]... [--count N] [--seconds S] [--until-scene]
//
// URL is ws://HOST:PORT/ (with ?token=... for control). On the server's first advertisement it
// subscribes to /octo_delta/vehicle and /octo_delta/log, then publishes each --publish text as
// it is (not checked: junk is for the server to refuse) on a /octo_delta/requests channel it
// advertises (encoding json), then subscribes to /octo_delta/view. The server handles a
// client's messages in order, so once it has seen the scene subscription it has handled the
// requests before it; and a server that answers a request on its log is heard.
//
// One JSON line on stdout for each thing that happens:
//   {"topic":"/octo_delta/view","t_ns":T,"bytes":B,"entities":N,"deletions":M,"cubes":K}
//   {"topic":"/octo_delta/vehicle","t_ns":T,"bytes":B,"frame_id":"map","position":[x,y,z],
//    "orientation":[x,y,z,w]}
//   {"topic":"/octo_delta/log","t_ns":T,"bytes":B,"level":L,"message":"..."}
//   {"topic":...,"t_ns":T,"bytes":B,"error":"..."}   a message that is not the JSON expected
//   {"status":"...","level":L}                         a status from the server (0 info,
//                                                      1 warning, 2 error)
//   {"published":true,"requests":N}                   after the --publish texts were sent
//   {"closed":true}                                   the server closed the connection
// T is the message's log time in ns, exactly.
//
// It ends, exit 0, once N messages (on the three topics) have come with --count N (at once
// after publishing with --count 0), after S seconds with --seconds S, when the server closes
// the connection, when a scene message with entities has come with --until-scene, or when
// killed. Exit 1 (the reason on stderr) if it cannot connect, 2 on a
// bad command line.
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const SCENE = "/octo_delta/view";
const POSE = "/octo_delta/vehicle";
const LOG = "/octo_delta/log";
const REQUESTS = "/octo_delta/requests";

function usage(why) {
  console.error(`map_client: ${why}`);
  console.error("usage: node map_client.mjs URL [--publish JSONTEXT]... [--count N] [--seconds S] [--until-scene]");
  process.exit(2);
}

function args(argv) {
  const out = { url: null, publish: [], count: null, seconds: null, untilScene: false };
  for (let i = 2; i < argv.length; i++) {
    const flag = argv[i];
    if (!flag.startsWith("--")) {
      if (out.url !== null) usage(`one URL expected, found another: ${flag}`);
      out.url = flag;
      continue;
    }
    if (flag === "--until-scene") {
      out.untilScene = true;
      continue;
    }
    const value = argv[++i];
    if (value === undefined) usage(`${flag} needs a value`);
    const number = Number(value);
    if (flag === "--publish") out.publish.push(value);
    else if (flag === "--count" && Number.isInteger(number) && number >= 0) out.count = number;
    else if (flag === "--seconds" && number > 0) out.seconds = number;
    else usage(`unknown flag or bad value: ${flag} ${value}`);
  }
  if (out.url === null) usage("no URL");
  return out;
}

// One line of JSON; a bigint (a log time in ns) is written as its exact digits.
function say(object) {
  const text = JSON.stringify(object, (_, v) => (typeof v === "bigint" ? `@big:${v}` : v));
  process.stdout.write(text.replace(/"@big:(-?\d+)"/g, "$1") + "\n");
}

function describe(topic, text) {
  const json = JSON.parse(text);
  if (topic === SCENE) {
    const entities = Array.isArray(json.entities) ? json.entities : [];
    return {
      entities: entities.length,
      deletions: Array.isArray(json.deletions) ? json.deletions.length : 0,
      cubes: entities.reduce((n, e) => n + (Array.isArray(e.cubes) ? e.cubes.length : 0), 0),
    };
  }
  if (topic === POSE) {
    const { position: p = {}, orientation: q = {} } = json.pose ?? {};
    return { frame_id: json.frame_id, position: [p.x, p.y, p.z], orientation: [q.x, q.y, q.z, q.w] };
  }
  return { level: json.level, message: json.message };
}

const opts = args(process.argv);
const ws = new WebSocket(opts.url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const topics = new Map(); // subscription id -> topic
const decoder = new TextDecoder();
let received = 0;
let started = false;
let ending = false;

function end() {
  if (ending) return;
  ending = true;
  ws.on("close", () => process.exit(0));
  client.close();
  // A server that does not answer the close is not waited for.
  setTimeout(() => process.exit(0), 2000).unref();
}

function subscribe(channels, wanted) {
  for (const c of channels) {
    if (wanted.includes(c.topic)) topics.set(client.subscribe(c.id), c.topic);
  }
}

client.on("error", (e) => {
  console.error(`map_client: ${e?.message ?? e}`);
  process.exit(1);
});
client.on("close", () => {
  if (!ending) {
    say({ closed: true });
    process.exit(0);
  }
});
client.on("status", (s) => say({ status: s.message, level: s.level }));
client.on("advertise", (channels) => {
  subscribe(channels, [POSE, LOG]);
  if (!started) {
    started = true;
    if (opts.publish.length > 0) {
      const channel = client.advertise({ topic: REQUESTS, encoding: "json", schemaName: "" });
      const encoder = new TextEncoder();
      for (const text of opts.publish) client.sendMessage(channel, encoder.encode(text));
      say({ published: true, requests: opts.publish.length });
    }
    if (opts.seconds !== null) setTimeout(end, opts.seconds * 1000);
  }
  subscribe(channels, [SCENE]);
  if (opts.count === 0) end();
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = topics.get(subscriptionId);
  if (topic === undefined || ending) return;
  const text = decoder.decode(data);
  const line = { topic, t_ns: timestamp, bytes: data.byteLength };
  try {
    Object.assign(line, describe(topic, text));
  } catch (e) {
    line.error = String(e?.message ?? e);
  }
  say(line);
  received += 1;
  if (opts.count !== null && received >= opts.count) end();
  if (opts.untilScene && topic === SCENE && line.entities > 0) end();
});
