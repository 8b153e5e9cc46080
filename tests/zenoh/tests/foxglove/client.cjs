// A Foxglove WebSocket client that is not ours: @foxglove/ws-protocol's
// FoxgloveClient over the `ws` package, validating every message against its
// channel's JSON Schema with Ajv. Run by tests/zenoh/tests/all/foxglove.rs with NODE_PATH
// at the packages `.ci/run` installs (target/foxglove-client/node_modules).
//
// Usage: node client.cjs ws://127.0.0.1:PORT
// It prints one JSON line per thing it sees (`kind`: open, serverInfo, advertise,
// message, status, parameterValues, services, serviceCallResponse,
// serviceCallFailure, close, error) and does what each JSON line of stdin says
// (`do`: subscribe, unsubscribe, getParameters, setParameters, call). An advertised
// channel's `schemaError` says why Ajv could not compile its schema, its
// `viewerError` why the Foxglove and Lichtblick viewers would refuse it.

"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const Ajv2020 = require("ajv/dist/2020").default;
const readline = require("node:readline");

const ajv = new Ajv2020({ strict: false, allErrors: true });
const out = (fields) => process.stdout.write(JSON.stringify(fields) + "\n");

// The Foxglove SDK's server speaks the protocol as `foxglove.sdk.v1`, the same
// protocol as the spec's `foxglove.websocket.v1` under a new name (the client checks
// no name itself since 0.7.5); the Foxglove app and Lichtblick offer both.
const client = new FoxgloveClient({
  ws: new WebSocket(process.argv[2], ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});

// Channels by id and by topic; each subscription's channel and how many of its
// messages are still to be printed.
const channels = new Map();
const byTopic = new Map();
const subscriptions = new Map();
const services = new Map();
const decoder = new TextDecoder();

client.on("open", () => out({ kind: "open" }));
client.on("error", (error) => out({ kind: "error", message: String(error && error.message) }));
client.on("close", () => {
  out({ kind: "close" });
  process.exit(0);
});
client.on("serverInfo", (info) =>
  out({ kind: "serverInfo", name: info.name, capabilities: info.capabilities }),
);
client.on("status", (status) => out({ kind: "status", level: status.level, message: status.message }));
// Why the Foxglove and Lichtblick viewers would refuse a channel's JSON Schema, or
// null: the rules of their `parseJsonSchema` (which refuses the whole channel for one
// property it cannot read): an object with `properties`, each with one `type`,
// `boolean`, `string` (no `contentEncoding` but base64), `number`, `integer`, `object`
// or `array` (of one of the others but `array`, with no `contentEncoding`), or a
// `oneOf` of numeric `const`s.
function viewerError(schema, at) {
  if (schema.type !== "object") {
    return `${at}: "type" is ${JSON.stringify(schema.type)}, not "object"`;
  }
  // Lichtblick reads a missing `properties` as none; Foxglove Studio throws.
  if (typeof schema.properties !== "object" || schema.properties === null) {
    return `${at}: no "properties"`;
  }
  for (const [name, property] of Object.entries(schema.properties)) {
    const where = `${at}.${name}`;
    if (Array.isArray(property.oneOf)) {
      if (!property.oneOf.every((alternative) => typeof alternative.const === "number")) {
        return `${where}: oneOf alternatives must have number values`;
      }
      continue;
    }
    switch (property.type) {
      case "string":
        if (property.contentEncoding !== undefined && property.contentEncoding !== "base64") {
          return `${where}: contentEncoding ${JSON.stringify(property.contentEncoding)}`;
        }
        break;
      case "boolean":
      case "number":
      case "integer":
        break;
      case "object": {
        const nested = viewerError(property, where);
        if (nested) return nested;
        break;
      }
      case "array": {
        const items = property.items ?? {};
        if (items.type === "object") {
          const nested = viewerError(items, where);
          if (nested) return nested;
        } else if (!["boolean", "string", "number", "integer"].includes(items.type)) {
          return `${where}: an array of ${JSON.stringify(items.type)}`;
        } else if (items.contentEncoding !== undefined) {
          return `${where}: items with a contentEncoding`;
        }
        break;
      }
      default:
        return `${where}: unsupported type ${JSON.stringify(property.type)}`;
    }
  }
  return null;
}

client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    let validate = null;
    let schemaError = null;
    let viewer = null;
    try {
      const schema = JSON.parse(channel.schema);
      viewer = viewerError(schema, channel.schemaName);
      validate = ajv.compile(schema);
    } catch (error) {
      schemaError = String(error.message);
    }
    channels.set(channel.id, { ...channel, validate });
    byTopic.set(channel.topic, channel.id);
    out({
      kind: "advertise",
      id: channel.id,
      topic: channel.topic,
      encoding: channel.encoding,
      schemaName: channel.schemaName,
      schemaEncoding: channel.schemaEncoding,
      schemaError,
      viewerError: viewer,
    });
  }
});
client.on("unadvertise", (ids) => out({ kind: "unadvertise", ids }));
client.on("message", ({ subscriptionId, data }) => {
  const subscription = subscriptions.get(subscriptionId);
  if (!subscription || subscription.left <= 0) {
    return;
  }
  subscription.left -= 1;
  const channel = channels.get(subscription.channelId);
  const text = decoder.decode(data);
  let value = null;
  let valid = false;
  let errors = null;
  try {
    value = JSON.parse(text);
    valid = channel.validate ? channel.validate(value) : false;
    errors = valid ? null : channel.validate ? channel.validate.errors : "no schema";
  } catch (error) {
    errors = String(error.message);
  }
  out({ kind: "message", topic: channel.topic, valid, errors, data: value });
});
client.on("parameterValues", ({ parameters, id }) => out({ kind: "parameterValues", parameters, id }));
client.on("advertiseServices", (advertised) => {
  for (const service of advertised) {
    services.set(service.name, service);
  }
  out({ kind: "services", services: advertised.map((s) => ({ id: s.id, name: s.name })) });
});
client.on("serviceCallResponse", (response) =>
  out({
    kind: "serviceCallResponse",
    callId: response.callId,
    encoding: response.encoding,
    data: decoder.decode(response.data),
  }),
);
client.on("serviceCallFailure", (failure) =>
  out({ kind: "serviceCallFailure", callId: failure.callId, message: failure.message }),
);

readline.createInterface({ input: process.stdin }).on("line", (line) => {
  const order = JSON.parse(line);
  switch (order.do) {
    case "subscribe": {
      const channelId = byTopic.get(order.topic);
      if (channelId === undefined) {
        out({ kind: "error", message: `no channel ${order.topic}` });
        return;
      }
      const id = client.subscribe(channelId);
      subscriptions.set(id, { channelId, left: order.count ?? 1000000, topic: order.topic });
      out({ kind: "subscribed", topic: order.topic, subscriptionId: id });
      break;
    }
    case "unsubscribe": {
      for (const [id, subscription] of subscriptions) {
        if (subscription.topic === order.topic) {
          client.unsubscribe(id);
          subscriptions.delete(id);
        }
      }
      out({ kind: "unsubscribed", topic: order.topic });
      break;
    }
    case "getParameters":
      client.getParameters(order.names, order.id);
      break;
    case "setParameters":
      client.setParameters(order.parameters, order.id);
      break;
    case "call": {
      const service = services.get(order.service);
      if (!service) {
        out({ kind: "error", message: `no service ${order.service}` });
        return;
      }
      client.sendServiceCallRequest({
        serviceId: service.id,
        callId: order.callId,
        encoding: "json",
        data: new TextEncoder().encode(JSON.stringify(order.request)),
      });
      break;
    }
    case "close":
      client.close();
      break;
    default:
      out({ kind: "error", message: `unknown order ${order.do}` });
  }
});
