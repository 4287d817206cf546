// Foxglove's JSON-schema parser, as Foxglove Studio runs it on a channel's schema, over the
// schemas given on stdin ({"name": schema, ...}); prints {"name": {"ok": true, "datatypes":
// {type: [field, ...]}} or {"ok": false, "error": "..."}, ...}.
//
// The parser is the published npm package @foxglove/studio-base's own (installed into
// dashboard/node_modules by `make`): its bundle concatenates the module
// ../mcap-support/src/parseJsonSchema.ts, whose function parseJsonSchema(schema, typeName) is
// read from the installed file and evaluated here with its one dependency,
// @protobufjs/base64. Nothing of it is kept in this repository.
"use strict";

const fs = require("fs");
const path = require("path");

const DASHBOARD = path.join(__dirname, "..", "..", "dashboard");
const MODULE = ";// CONCATENATED MODULE: ../mcap-support/src/parseJsonSchema.ts";
const NEXT = ["\n// EXTERNAL MODULE:", "\n;// CONCATENATED MODULE:"];

function packageDir(name) {
  const manifest = require.resolve(`${name}/package.json`, { paths: [DASHBOARD] });
  return path.dirname(manifest);
}

function parserSource() {
  const assets = path.join(packageDir("@foxglove/studio-base"), "assets");
  const files = fs
    .readdirSync(assets)
    .filter((name) => name.endsWith(".js"))
    .map((name) => path.join(assets, name))
    .sort((a, b) => fs.statSync(a).size - fs.statSync(b).size);
  for (const file of files) {
    const text = fs.readFileSync(file, "utf8");
    const start = text.indexOf(MODULE);
    if (start < 0) continue;
    const ends = NEXT.map((mark) => text.indexOf(mark, start + MODULE.length)).filter((i) => i > 0);
    const source = text.slice(start + MODULE.length, Math.min(...ends));
    if (!source.includes("function parseJsonSchema(")) break;
    return { file, source };
  }
  throw new Error(`no ${MODULE.slice(3)} in ${assets}`);
}

function loadParser() {
  const { file, source } = parserSource();
  const base64 = require(packageDir("@protobufjs/base64"));
  const parse = new Function("base64", `${source}\nreturn parseJsonSchema;`)(base64);
  return { file, parse };
}

function main() {
  const schemas = JSON.parse(fs.readFileSync(0, "utf8"));
  const { file, parse } = loadParser();
  const results = {};
  for (const [name, schema] of Object.entries(schemas)) {
    try {
      const { datatypes } = parse(schema, name);
      const types = {};
      for (const [type, { definitions }] of datatypes) types[type] = definitions;
      results[name] = { ok: true, datatypes: types };
    } catch (err) {
      results[name] = { ok: false, error: String(err && err.message ? err.message : err) };
    }
  }
  process.stdout.write(JSON.stringify({ parser: file, results }));
}

main();
