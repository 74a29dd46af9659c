// Reads an MCAP file with @mcap/core's McapStreamReader (an independent reader, CRCs checked)
// and prints, for tests/emulator/scoring/run_mcap_test.cc, one line per channel:
//     <topic> <schema name> <schema encoding> <message encoding> <messages> <first log_time ns> <last log_time ns>
// then "records <n>" and "json-ok" when every message parses as JSON.
// Usage: node mcap_read.js MODULE_DIR FILE (MODULE_DIR: where node_modules/@mcap/core is).
const path = require("path");
const fs = require("fs");
const { McapStreamReader } = require(path.resolve(process.argv[2], "node_modules", "@mcap", "core"));

const reader = new McapStreamReader({ validateCrcs: true });
reader.append(new Uint8Array(fs.readFileSync(process.argv[3])));
const schemas = new Map();
const channels = new Map();
let records = 0;
let jsonOk = true;
const decoder = new TextDecoder();
for (let r; (r = reader.nextRecord()); ) {
  records++;
  if (r.type === "Schema") schemas.set(r.id, r);
  if (r.type === "Channel") channels.set(r.id, { ...r, count: 0, first: null, last: null });
  if (r.type === "Message") {
    const c = channels.get(r.channelId);
    c.count++;
    if (c.first === null) c.first = r.logTime;
    c.last = r.logTime;
    try {
      JSON.parse(decoder.decode(r.data));
    } catch (e) {
      jsonOk = false;
    }
  }
}
if (!reader.done()) {
  console.log("not done: the file ends inside a record");
  process.exit(1);
}
for (const c of channels.values()) {
  const s = schemas.get(c.schemaId);
  console.log(c.topic, s.name, s.encoding, c.messageEncoding, c.count, String(c.first), String(c.last));
}
console.log("records", records);
if (jsonOk) console.log("json-ok");
