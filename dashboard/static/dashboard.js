// The team dashboard's page: a WebSocket of frames from the server (dashboard/app.py), the
// time charts drawn with uPlot, the phase timeline, top view and graph with Plotly (both
// served by the app: uPlot installed from the npm registry, Plotly from the plotly package).
//
// Memory is bounded: a time chart keeps at most MAX_COLUMNS instants (the server sends at most
// MAX_POINTS points per trace), and the points that arrive while paused wait in the same
// arrays (paused, only the drawing stops).
"use strict";

const MAX_POINTS = 3000;
const CHART_EVERY_MS = 100; // time charts redraw at most 10 times a second
const SCENE_EVERY_MS = 200; // top view and table at most 5 times a second
const SLOW_EVERY_MS = 1000; // graph and timeline: on a change, else once a second
const RECEIPTS = 5000; // frames' arrival times and redraw times kept, for measurements

// 16 hues that stay apart on a dark background; robots 17..32 reuse them dashed.
const COLOURS = [
  "#4e9bff", "#ff6b6b", "#5fd35f", "#ffb020", "#c77dff", "#2ee6d6", "#ff85c8", "#e8e85a",
  "#b08060", "#a8b3c2", "#8a6cff", "#ff8f5a", "#2fa37a", "#f0c0ff", "#d0383a", "#1e90b0",
];
const PHASE_COLOURS = {
  excite: "#4e9bff", inertia: "#c77dff", push: "#ffb020", done: "#3fb950", halted: "#f85149",
};
const HEALTH_COLOURS = {
  ok: "#3fb950", late: "#d29922", silent: "#f85149", lost: "#f85149", ended: "#6e7681",
};
const TRUTH_COLOUR = "#f0f3f6";
const PLOT_CONFIG = { displaylogo: false, responsive: true, scrollZoom: true,
  modeBarButtonsToRemove: ["select2d", "lasso2d", "toImage"] };

function colour(robot) { return COLOURS[(robot - 1) % COLOURS.length]; }
function dash(robot) { return robot > COLOURS.length ? "dash" : "solid"; }
function token() { return new URLSearchParams(location.search).get("token"); }
function fmt(value, digits) {
  return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
}

function baseLayout(extra) {
  return Object.assign({
    paper_bgcolor: "rgba(0,0,0,0)", plot_bgcolor: "rgba(0,0,0,0)",
    font: { color: "#d8dde6", size: 11 },
    margin: { l: 48, r: 8, t: 6, b: 28 },
    showlegend: false, uirevision: "keep", hovermode: "closest",
    xaxis: { gridcolor: "#2a2f3a", zerolinecolor: "#3a4150", title: { text: "t (s)", standoff: 2 } },
    yaxis: { gridcolor: "#2a2f3a", zerolinecolor: "#3a4150" },
  }, extra || {});
}

// ------------------------------------------------------------------------ time charts
// The time charts are uPlot's (canvas: in heft bench --dashboard, 16 robots and three pages
// on two cores, a chart's redraw took p99 25 ms, where Plotly's SVG charts took 277 ms).
// uPlot draws a chart's traces on one shared x axis: a chart keeps the sorted
// union of its traces' times (the server's points are at ticks' times) and a column of values
// per trace, null where a trace has no point at that time (its line spans the gap).
const MAX_COLUMNS = 2 * MAX_POINTS; // the robots' points and the truth's may fall on different ticks
const DASHES = { solid: null, dash: [6, 4], dot: [2, 3] };
const AXIS = {
  stroke: "#d8dde6", font: "11px system-ui, sans-serif",
  grid: { stroke: "#2a2f3a", width: 1 }, ticks: { stroke: "#2a2f3a", width: 1 },
};

function tickLabels(u, splits) {
  // as many decimals as the step between ticks needs: 0.25 stays 0.25, and m̂ settling to
  // 1e-5 of the truth gets 4.99999 and 5.00000 rather than 5 and 5
  const step = splits.length > 1 ? Math.abs(splits[1] - splits[0]) : 1;
  let decimals = Math.max(0, -Math.floor(Math.log10(step || 1)));
  while (decimals < 10 && Math.abs(step * 10 ** decimals - Math.round(step * 10 ** decimals)) > 1e-6) {
    decimals += 1;
  }
  return splits.map((v) => v.toFixed(decimals));
}

function labelWidth(u, values, axis, cycle) {
  // the y axis as wide as its longest tick label (uPlot calls this again once labels change)
  if (cycle > 1 || !values) return u.axes[axis]._size || 48;
  u.ctx.font = u.axes[axis].font[0]; // the font as uPlot scales it for the canvas
  const widest = values.reduce((w, v) => Math.max(w, u.ctx.measureText(String(v)).width), 0);
  return Math.ceil(widest / devicePixelRatio) + 16;
}

class TimeChart {
  constructor(id, quantity, describe) {
    this.div = document.getElementById(id);
    this.quantity = quantity; // trace ids are QUANTITY/...
    this.describe = describe; // trace id -> {name, colour, dash}
    this.plot = null;
    this.switches = []; // [t, colour] of the team's phase switches
    this.shown = null; // [first, last] time of the data last handed to uPlot
    new ResizeObserver(() => { if (this.plot) this.plot.setSize(this.size()); }).observe(this.div);
    this.reset();
  }
  reset() {
    this.traces = []; // trace ids, in column order
    this.index = new Map(); // trace id -> column
    this.x = [];
    this.ys = [];
    this.last = new Map(); // trace id -> newest t
    this.dirty = true;
    this.rebuild = true;
  }
  size() {
    return { width: Math.max(120, this.div.clientWidth), height: Math.max(80, this.div.clientHeight) };
  }
  column(t) {
    // the index of time t in this.x, inserted (null in every trace) if new
    const x = this.x, n = x.length;
    if (n === 0 || t > x[n - 1]) {
      x.push(t);
      for (const y of this.ys) y.push(null);
      return n;
    }
    let lo = 0, hi = n - 1;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (x[mid] < t) lo = mid + 1; else hi = mid;
    }
    if (x[lo] !== t) {
      x.splice(lo, 0, t);
      for (const y of this.ys) y.splice(lo, 0, null);
    }
    return lo;
  }
  add(trace, points) {
    let i = this.index.get(trace);
    if (i === undefined) {
      i = this.traces.length;
      this.index.set(trace, i);
      this.traces.push(trace);
      this.ys.push(new Array(this.x.length).fill(null));
      this.rebuild = true;
    }
    let last = this.last.has(trace) ? this.last.get(trace) : -Infinity;
    for (const [t, y] of points) {
      if (t <= last) continue; // already drawn (a hello and a frame may overlap)
      this.ys[i][this.column(t)] = y;
      last = t;
    }
    this.last.set(trace, last);
    const excess = this.x.length - MAX_COLUMNS;
    if (excess > 0) {
      this.x.splice(0, excess);
      for (const y of this.ys) y.splice(0, excess);
    }
    this.dirty = true;
  }
  zoomed() {
    // whether the x range shown is narrower than the data's (the user zoomed in)
    if (!this.plot || !this.shown) return false;
    const [first, last] = this.shown, scale = this.plot.scales.x;
    const slack = 1e-9 * Math.max(1, Math.abs(last - first));
    return scale.min > first + slack || scale.max < last - slack;
  }
  flush() {
    if (!this.dirty && !this.rebuild) return;
    const data = [this.x.slice(), ...this.ys.map((y) => y.slice())];
    const zoomed = this.zoomed();
    this.shown = this.x.length ? [this.x[0], this.x[this.x.length - 1]] : null;
    this.dirty = false;
    if (this.rebuild || !this.plot) this.build(data, zoomed);
    else this.plot.batch(() => this.plot.setData(data, !zoomed)); // drawn now, not in a microtask
  }
  build(data, zoomed) {
    const range = this.plot && zoomed ? [this.plot.scales.x.min, this.plot.scales.x.max] : null;
    if (this.plot) this.plot.destroy();
    this.rebuild = false;
    const series = [{ label: "t" }];
    for (const trace of this.traces) {
      const look = this.describe(trace);
      series.push({ label: look.name, stroke: look.colour, width: look.width || 1.6,
        dash: DASHES[look.dash || "solid"], spanGaps: true, points: { show: false } });
    }
    this.plot = new uPlot({
      ...this.size(),
      legend: { show: false },
      scales: { x: { time: false } },
      cursor: { drag: { x: true, y: false }, points: { show: false } },
      axes: [
        { ...AXIS, label: "t (s)", labelSize: 16, labelFont: AXIS.font, size: 30 },
        { ...AXIS, size: labelWidth, values: tickLabels },
      ],
      series,
      hooks: { draw: [(u) => this.drawSwitches(u)] },
    }, data, this.div);
    if (range) this.plot.setScale("x", { min: range[0], max: range[1] });
  }
  drawSwitches(u) {
    // the team's phase switches as dotted vertical lines
    const ctx = u.ctx, { left, top, width, height } = u.bbox;
    ctx.save();
    ctx.lineWidth = devicePixelRatio;
    ctx.setLineDash([2 * devicePixelRatio, 3 * devicePixelRatio]);
    for (const [t, colour] of this.switches) {
      const x = Math.round(u.valToPos(t, "x", true));
      if (x < left || x > left + width) continue;
      ctx.strokeStyle = colour;
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
    }
    ctx.restore();
  }
  setSwitches(switches) {
    if (JSON.stringify(switches) === JSON.stringify(this.switches)) return;
    this.switches = switches;
    if (this.plot) this.plot.redraw(false, false);
  }
  lines() {
    // [{name, x, y}] per trace: its points, in time order
    return this.traces.map((trace, i) => {
      const x = [], y = [];
      this.ys[i].forEach((value, k) => { if (value !== null) { x.push(this.x[k]); y.push(value); } });
      return { name: this.describe(trace).name, x, y };
    });
  }
  visible() {
    // [trace name, t, value] of the points inside the current x range
    const scale = this.plot ? this.plot.scales.x : null;
    const zoomed = this.zoomed();
    const rows = [];
    for (const line of this.lines()) {
      line.x.forEach((t, k) => {
        if (zoomed && (t < scale.min || t > scale.max)) return;
        rows.push([line.name, t, line.y[k]]);
      });
    }
    return rows;
  }
}

function robotTrace(label) {
  return (trace) => {
    const who = trace.split("/")[1];
    if (who === "truth") return { name: `${label} (truth)`, colour: TRUTH_COLOUR, dash: "dash", width: 1.2 };
    const robot = Number(who);
    return { name: `${label} robot ${robot}`, colour: colour(robot), dash: dash(robot) };
  };
}
function edgeTrace(trace) {
  const [, pair, truth] = trace.split("/");
  const [i, j] = pair.split("-").map(Number);
  if (truth) return { name: `‖z${i}${j}‖ (truth)`, colour: colour(i), dash: "dot", width: 1 };
  return { name: `‖ẑ${i}${j}‖ robot ${i}`, colour: colour(i), dash: dash(i) };
}

const charts = {
  mass: new TimeChart("chart-mass", "mass", robotTrace("m̂")),
  moment: new TimeChart("chart-moment", "moment", robotTrace("Ĵ")),
  edge: new TimeChart("chart-edge", "edge", edgeTrace),
  com: new TimeChart("chart-com", "com", robotTrace("‖ẑC‖")),
  omega: new TimeChart("chart-omega", "omega", robotTrace("ω")),
};

// ------------------------------------------------------------------------ the page's state
const heft = {
  scene: null, epoch: null, paused: false, frames: 0, receipts: [], charts: charts,
  lastShape: "", wake: null, socket: null,
  chartMs: [], sceneMs: [], // how long each redraw took (ms), the newest RECEIPTS
};
window.heft = heft;

function takePoints(points) {
  for (const [trace, list] of Object.entries(points)) {
    const chart = charts[trace.split("/")[0]];
    if (chart) chart.add(trace, list);
  }
}

function switchLines(scene) {
  const shapes = [];
  for (const [phase, t] of Object.entries(scene.switches || {})) {
    if (phase === "excite") continue;
    shapes.push({ type: "line", yref: "paper", y0: 0, y1: 1, x0: t, x1: t,
      line: { color: PHASE_COLOURS[phase] || "#888", width: 1, dash: "dot" } });
  }
  return shapes;
}

function drawSwitches(scene) {
  const switches = Object.entries(scene.switches || {})
    .filter(([phase]) => phase !== "excite")
    .map(([phase, t]) => [t, PHASE_COLOURS[phase] || "#888"]);
  for (const chart of Object.values(charts)) chart.setSwitches(switches);
}

// ------------------------------------------------------------------------ the phase timeline
function drawTimeline(scene) {
  const byPhase = {};
  const now = scene.t;
  const robots = Object.keys(scene.robots).map(Number).sort((a, b) => a - b);
  for (const robot of robots) {
    const segments = scene.robots[robot].segments;
    segments.forEach(([phase, start], k) => {
      const end = k + 1 < segments.length ? segments[k + 1][1] : Math.max(now, start);
      const bar = byPhase[phase] || (byPhase[phase] = { x: [], base: [], y: [] });
      bar.base.push(start); bar.x.push(Math.max(end - start, now * 0.002 + 1e-3));
      bar.y.push(`robot ${robot}`);
    });
  }
  const data = scene.phases.filter((p) => byPhase[p]).map((phase) => ({
    type: "bar", orientation: "h", name: phase, base: byPhase[phase].base,
    x: byPhase[phase].x, y: byPhase[phase].y, marker: { color: PHASE_COLOURS[phase] },
    hovertemplate: `${phase} from %{base:.2f} s<extra>%{y}</extra>`,
  }));
  Plotly.react("chart-phases", data, baseLayout({
    barmode: "overlay", showlegend: true, legend: { orientation: "h", y: 1.12, x: 0 },
    margin: { l: 64, r: 8, t: 18, b: 28 },
    yaxis: { autorange: "reversed", gridcolor: "#2a2f3a" },
    shapes: switchLines(scene),
  }), PLOT_CONFIG);
}

// ------------------------------------------------------------------------ the top view
function drawTop(scene) {
  const top = scene.top;
  document.getElementById("top-source").textContent = top
    ? (top.source === "truth" ? "world frame, truth and estimates" : "about p_G, estimates only") : "";
  if (!top) return;
  const data = [];
  if (top.outline) {
    const xs = top.outline.map((p) => p[0]), ys = top.outline.map((p) => p[1]);
    xs.push(xs[0]); ys.push(ys[0]);
    data.push({ type: "scatter", mode: "lines", name: "load", x: xs, y: ys, fill: "toself",
      fillcolor: "rgba(120,130,150,0.18)", line: { color: "#8a93a3", width: 1.5 }, hoverinfo: "skip" });
  }
  const contacts = top.contacts.map((p, k) => ({ p, robot: k + 1 })).filter((c) => c.p);
  data.push({ type: "scatter", mode: "markers+text", name: "contacts",
    x: contacts.map((c) => c.p[0]), y: contacts.map((c) => c.p[1]),
    text: contacts.map((c) => String(c.robot)), textposition: "top center",
    marker: { size: 10, color: contacts.map((c) => colour(c.robot)), line: { color: "#000", width: 1 } },
    hovertemplate: "contact %{text}: (%{x:.3f}, %{y:.3f})<extra></extra>" });
  const estimates = Object.entries(top.com_estimates || {});
  data.push({ type: "scatter", mode: "markers", name: "COM estimates",
    x: estimates.map(([, p]) => p[0]), y: estimates.map(([, p]) => p[1]),
    text: estimates.map(([r]) => r),
    marker: { size: 9, symbol: "circle-open", line: { width: 2 },
      color: estimates.map(([r]) => colour(Number(r))) },
    hovertemplate: "robot %{text}'s p̂_C: (%{x:.3f}, %{y:.3f})<extra></extra>" });
  if (top.com) {
    data.push({ type: "scatter", mode: "markers", name: "COM (truth)", x: [top.com[0]], y: [top.com[1]],
      marker: { size: 13, symbol: "x-thin", line: { width: 2.5, color: TRUTH_COLOUR } },
      hovertemplate: "p_C (truth): (%{x:.3f}, %{y:.3f})<extra></extra>" });
  }
  // The commanded forces as arrows: a shaft and a two-stroke head, a line trace per robot,
  // the largest a quarter of the load's size (the forces' directions and ratios, not newtons).
  const forces = Object.entries(top.forces || {});
  const corners = top.outline || contacts.map((c) => c.p);
  const span = (k) => Math.max(...corners.map((p) => p[k])) - Math.min(...corners.map((p) => p[k]));
  const size = corners.length ? Math.max(span(0), span(1), 0.5) : 1;
  const largest = Math.max(0, ...forces.map(([, f]) => Math.hypot(f[0], f[1])));
  const scale = largest > 1e-6 ? (0.25 * size) / largest : 0; // metres per newton
  for (const [robot, force] of forces) {
    const c = top.contacts[Number(robot) - 1];
    const length = Math.hypot(force[0], force[1]);
    if (!c || length < 1e-6) continue;
    const tip = [c[0] + scale * force[0], c[1] + scale * force[1]];
    const head = 0.3 * scale * length, u = [force[0] / length, force[1] / length];
    const side = (sign) => [tip[0] - head * (u[0] * 0.87 - sign * u[1] * 0.5),
      tip[1] - head * (u[1] * 0.87 + sign * u[0] * 0.5)];
    const [left, right] = [side(1), side(-1)];
    data.push({ type: "scatter", mode: "lines", name: `force ${robot}`, hoverinfo: "skip",
      x: [c[0], tip[0], null, left[0], tip[0], right[0]],
      y: [c[1], tip[1], null, left[1], tip[1], right[1]],
      line: { color: colour(Number(robot)), width: 2 } });
  }
  Plotly.react("top", data, baseLayout({
    margin: { l: 36, r: 8, t: 6, b: 24 }, uirevision: "top",
    xaxis: { gridcolor: "#2a2f3a", zerolinecolor: "#3a4150" },
    yaxis: { gridcolor: "#2a2f3a", zerolinecolor: "#3a4150", scaleanchor: "x", scaleratio: 1 },
  }), PLOT_CONFIG);
}

// ------------------------------------------------------------------------ the graph
function drawGraph(scene) {
  const n = scene.n || Object.keys(scene.robots).length;
  if (!n) return;
  const at = (i) => [Math.cos(Math.PI / 2 - (2 * Math.PI * (i - 1)) / n),
    Math.sin(Math.PI / 2 - (2 * Math.PI * (i - 1)) / n)];
  const data = [], annotations = [];
  // One line trace per health (the links' segments split by nulls), not one per link: with
  // 16 robots in heft bench --dashboard, a redraw of the graph went from p50 77-96 ms to 42-47.
  const byHealth = {};
  for (const link of scene.links) {
    const [i, j] = link.edge, a = at(i), b = at(j);
    const info = `${i}–${j}: ${link.health}, age ${link.age_s === null ? "–" : link.age_s.toFixed(2) + " s"}, ${link.rate_hz} msg/s`;
    const lines = byHealth[link.health] || (byHealth[link.health] = { x: [], y: [], text: [] });
    lines.x.push(a[0], b[0], null); lines.y.push(a[1], b[1], null); lines.text.push(info, info, null);
    if (scene.links.length <= 12) {
      annotations.push({ x: (a[0] + b[0]) / 2, y: (a[1] + b[1]) / 2, showarrow: false,
        text: `${link.age_s === null ? "–" : link.age_s.toFixed(2)} s · ${link.rate_hz}/s`,
        font: { size: 10, color: HEALTH_COLOURS[link.health] || "#888" }, bgcolor: "rgba(17,19,24,0.8)" });
    }
  }
  for (const [health, lines] of Object.entries(byHealth)) {
    data.push({ type: "scatter", mode: "lines", x: lines.x, y: lines.y, text: lines.text,
      line: { color: HEALTH_COLOURS[health] || "#888", width: 3 }, hoverinfo: "text" });
  }
  const ids = Array.from({ length: n }, (_, k) => k + 1);
  const lost = new Set();
  for (const alarm of scene.alarms) {
    const m = /robot\(s\) \[([\d, ]+)\] lost/.exec(alarm.text);
    if (m) m[1].split(",").forEach((r) => lost.add(Number(r)));
  }
  data.push({ type: "scatter", mode: "markers+text", x: ids.map((i) => at(i)[0]), y: ids.map((i) => at(i)[1]),
    text: ids.map(String), textfont: { color: "#0c0e12", size: 11 },
    marker: { size: 24, color: ids.map(colour), line: { width: 3, color: ids.map((i) => (lost.has(i) ? "#f85149" : "#0c0e12")) } },
    hovertemplate: "robot %{text}<extra></extra>" });
  Plotly.react("graph", data, baseLayout({
    margin: { l: 4, r: 4, t: 4, b: 4 }, annotations: annotations, uirevision: "graph",
    xaxis: { visible: false, range: [-1.35, 1.35] },
    yaxis: { visible: false, range: [-1.25, 1.25], scaleanchor: "x" },
  }), { displayModeBar: false, responsive: true });
}

// ------------------------------------------------------------------------ the table
function drawTable(scene) {
  const table = scene.table;
  const title = document.getElementById("table-title");
  title.innerHTML = table.final
    ? `<span class="final">final</span> estimates against truth (t = ${fmt(table.t, 2)} s)`
    : "latest estimates against truth";
  const rows = [`<tr><th>robot</th><th>phase</th><th>m̂ kg</th><th>Ĵ kg m²</th>`
    + `<th title="|m̂ − m| / m">m %</th><th title="|Ĵ − J| / J">J %</th>`
    + `<th title="‖(p̂_C − p_Ci) − (p_C − p_Ci)‖">c mm</th><th title="max_j ‖ẑ_ij − z_ij‖">z mm</th></tr>`];
  for (const [robot, row] of Object.entries(table.robots)) {
    const e = row.errors || {};
    const c = row.contact_to_com ? `p̂_C − p_C${robot} = (${fmt(row.contact_to_com[0], 4)}, ${fmt(row.contact_to_com[1], 4)}) m` : "";
    rows.push(`<tr title="${c}"><td><span class="swatch" style="background:${colour(Number(robot))}"></span>${robot}</td>`
      + `<td style="color:${PHASE_COLOURS[row.phase] || "inherit"}">${row.phase}</td>`
      + `<td>${fmt(row.mass, 4)}</td><td>${fmt(row.moment, 4)}</td>`
      + `<td>${fmt(e.mass_pct, 3)}</td><td>${fmt(e.moment_pct, 3)}</td>`
      + `<td>${fmt(e.contact_to_com_mm, 2)}</td><td>${fmt(e.z_ij_mm, 2)}</td></tr>`);
  }
  if (table.truth) {
    rows.push(`<tr class="truth"><td>truth</td><td></td><td>${fmt(table.truth.mass, 4)}</td>`
      + `<td>${fmt(table.truth.moment, 4)}</td><td colspan="4"></td></tr>`);
  }
  document.getElementById("table").innerHTML = rows.join("");
}

// ------------------------------------------------------------------------ header and alarms
function drawHeader(scene, source) {
  document.getElementById("team").textContent = scene.team ? `team ${scene.team}` : "";
  document.getElementById("clock").textContent = `t = ${fmt(scene.t, 2)} s`;
  const badge = document.getElementById("source");
  if (source.mode === "replay") {
    const speed = source.speed === 0 ? "max" : `${source.speed}×`;
    badge.textContent = `REPLAY ${speed}${source.paused ? " · paused" : ""}${source.finished ? " · end" : ""}`
      + ` · ${fmt(source.position_s, 1)} s`;
    badge.className = "badge replay";
  } else {
    badge.textContent = "LIVE";
    badge.className = "badge live";
  }
  document.getElementById("replay-controls").hidden = !source.recording;
  document.getElementById("replay-toggle").textContent = source.paused ? "▶" : "❚❚";
  const phases = {};
  for (const [robot, view] of Object.entries(scene.robots)) {
    if (view.phase) (phases[view.phase] = phases[view.phase] || []).push(robot);
  }
  const names = Object.keys(phases);
  const chip = document.getElementById("team-phase");
  chip.textContent = names.length === 1 ? names[0] : names.map((p) => `${p} ${phases[p].join(",")}`).join(" · ") || "–";
  chip.style.background = names.length === 1 ? PHASE_COLOURS[names[0]] + "55" : "";
  const box = document.getElementById("alarms");
  box.hidden = !scene.alarms.length;
  box.innerHTML = scene.alarms.map((a) => `<div class="alarm ${a.level}">⚠ ${a.text}</div>`).join("");
}

// ------------------------------------------------------------------------ drawing
// One drawing job per animation frame, the most overdue first: a page never blocks for longer
// than its slowest job (so frames keep arriving on time), and each job waits at least BUDGET
// times its own last duration before it runs again (a big team's charts redraw less often
// rather than starve the page).
const BUDGET = 4;
const jobs = [
  ...Object.entries(charts).map(([name, chart]) => ({
    name, every: CHART_EVERY_MS, chart: true, run: () => chart.flush() })),
  { name: "top", every: SCENE_EVERY_MS, run: () => drawTop(heft.scene) },
  { name: "table", every: SCENE_EVERY_MS, run: () => drawTable(heft.scene) },
  { name: "switches", every: SLOW_EVERY_MS, run: () => drawSwitches(heft.scene) },
  { name: "timeline", every: SLOW_EVERY_MS, changes: true, run: () => drawTimeline(heft.scene) },
  { name: "graph", every: SLOW_EVERY_MS, changes: true, run: () => drawGraph(heft.scene) },
];
for (const job of jobs) { job.last = -Infinity; job.took = 0; }

function sceneShape(scene) {
  return JSON.stringify([scene.switches, scene.links.map((l) => l.health),
    Object.values(scene.robots).map((r) => r.segments.length), scene.alarms.length]);
}

function render(force) {
  const now = performance.now();
  if (!heft.scene) return;
  drawHeader(heft.scene, heft.source);
  if (heft.paused) return;
  const shape = sceneShape(heft.scene);
  const changed = shape !== heft.lastShape;
  heft.lastShape = shape;
  let next = null, wait = Infinity;
  for (const job of jobs) {
    if (force || (changed && job.changes)) job.last = -Infinity;
    const due = job.last + Math.max(job.every, BUDGET * job.took);
    if (due <= now && (!next || due < next.due)) next = Object.assign(job, { due });
    else if (due > now) wait = Math.min(wait, due - now);
  }
  if (next) {
    const started = performance.now();
    next.run();
    next.took = performance.now() - started;
    next.last = started;
    (next.chart ? heft.chartMs : heft.sceneMs).push(next.took);
    schedule();
  } else if (wait < Infinity) {
    clearTimeout(heft.wake);
    heft.wake = setTimeout(schedule, wait);
  }
}
let scheduled = false;
function schedule() {
  if (scheduled) return;
  scheduled = true;
  requestAnimationFrame(() => { scheduled = false; render(false); });
}

function onMessage(event) {
  const message = JSON.parse(event.data);
  heft.frames += 1;
  heft.receipts.push([Date.now(), message.sent_ms || null,
    message.scene ? Object.fromEntries(Object.entries(message.scene.robots).map(([r, v]) => [r, v.tick])) : null]);
  for (const ring of [heft.receipts, heft.chartMs, heft.sceneMs]) {
    if (ring.length > RECEIPTS) ring.splice(0, ring.length - RECEIPTS);
  }
  if (message.type === "hello") {
    if (heft.epoch !== null && message.epoch !== heft.epoch) {
      for (const chart of Object.values(charts)) chart.reset();
    }
    heft.epoch = message.epoch;
    takePoints(message.series);
  } else if (message.epoch !== heft.epoch) {
    heft.socket.close(); // a new replay: reconnect for its hello
    return;
  } else {
    takePoints(message.points);
  }
  heft.scene = message.scene;
  heft.source = message.source;
  schedule();
}

function connect() {
  const base = location.pathname.replace(/[^/]*$/, "");
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${base}ws${location.search}`;
  const socket = new WebSocket(url);
  heft.socket = socket;
  socket.onmessage = onMessage;
  socket.onclose = () => {
    const badge = document.getElementById("source");
    badge.textContent = "disconnected: retrying";
    badge.className = "badge down";
    setTimeout(connect, 1000);
  };
}

// ------------------------------------------------------------------------ controls
function exportCsv() {
  const lines = ["chart,trace,t_s,value"];
  for (const [name, chart] of Object.entries(charts)) {
    for (const [trace, t, value] of chart.visible()) lines.push(`${name},"${trace}",${t},${value}`);
  }
  return lines.join("\n") + "\n";
}
heft.csv = exportCsv;

document.getElementById("pause").onclick = (event) => {
  heft.paused = !heft.paused;
  event.target.textContent = heft.paused ? "▶ resume" : "❚❚ pause";
  event.target.classList.toggle("active", heft.paused);
  if (!heft.paused) { for (const job of jobs) job.last = -Infinity; schedule(); }
};
document.getElementById("export").onclick = () => {
  const blob = new Blob([exportCsv()], { type: "text/csv" });
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = `heft-${heft.scene ? heft.scene.team : "team"}-${new Date().toISOString().slice(0, 19)}.csv`;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
};

async function replay(body) {
  const headers = { "Content-Type": "application/json" };
  if (token()) headers["X-Heft-Token"] = token();
  const response = await fetch("api/replay", { method: "POST", headers, body: JSON.stringify(body) });
  if (!response.ok) {
    const reason = await response.json().catch(() => ({ detail: response.statusText }));
    alert(`replay: ${typeof reason.detail === "string" ? reason.detail : JSON.stringify(reason.detail)}`);
  }
}
const speedOf = () => Number(document.getElementById("replay-speed").value);
document.getElementById("replay-restart").onclick = () => replay({ action: "restart", speed: speedOf() });
document.getElementById("replay-toggle").onclick = () =>
  replay(heft.source && heft.source.paused ? { action: "play", speed: speedOf() } : { action: "pause" });
document.getElementById("replay-step").onclick = () => replay({ action: "step", seconds: 0.5 });
document.getElementById("replay-speed").onchange = () => {
  if (heft.source && heft.source.mode === "replay" && !heft.source.paused) replay({ action: "play", speed: speedOf() });
};

connect();
