// The team dashboard's page: a WebSocket of frames from the server (dashboard/app.py), every
// chart and view drawn with uPlot (installed from the npm registry, served by the app).
//
// Memory is bounded: a time chart keeps at most MAX_COLUMNS instants (the server sends at most
// MAX_POINTS points per trace), and the points that arrive while paused wait in the same
// arrays (paused, only the drawing stops).
//
// The estimated scalars (m̂, Ĵ, and whatever dashboard/quantities.py declares) come with the
// hello: each gets a time chart and columns of the table. A point [t, value, h] carries its
// 95 % interval value ± h, drawn as a band in the robot's colour.
"use strict";

const MAX_POINTS = 3000;
const CHART_EVERY_MS = 200; // time charts redraw at most 5 times a second
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
function colour(robot) { return COLOURS[(robot - 1) % COLOURS.length]; }
function dash(robot) { return robot > COLOURS.length ? "dash" : "solid"; }
function token() { return new URLSearchParams(location.search).get("token"); }
function fmt(value, digits) {
  return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
}

// An error in the results' units (a fraction, metres) as the table shows it (%, mm).
function scaled(value, factor) {
  return value === null || value === undefined ? value : value * factor;
}
// Whether h can be the half-width of a 95 % interval about value (anything else: none drawn).
function halfWidth(value, h) {
  return typeof h === "number" && h >= 0 && Number.isFinite(value - h) && Number.isFinite(value + h);
}
// A colour of ours ("#rrggbb") made translucent, for a band.
function faded(hex) { return `${hex}2a`; }

// ------------------------------------------------------------------------ time charts
// The time charts are uPlot's (canvas: in heft bench --dashboard, 16 robots and three pages
// on two cores, a chart's redraw took p99 25 ms, where Plotly's SVG charts took 277 ms).
// uPlot draws a chart's traces on one shared x axis: a chart keeps the sorted
// union of its traces' times (the server's points are at ticks' times) and a column of values
// per trace, null where a trace has no point at that time (its line spans the gap). A trace
// whose robot published an uncertainty gets two more columns, value − h and value + h, drawn
// as a uPlot band under the lines (from its first point with an h; where a later point has
// none, the band narrows to the line). The y range holds the lines and each band where the
// shown x range ends (how sure each robot is then), not the wider bands of earlier times.
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
  // the y axis as wide as its longest tick label (uPlot calls this again once labels change,
  // and again within one layout, at most 3 times, as the other axes' sizes change the y
  // axis' ticks: then it only widens, so that the layout settles and no label is cut)
  const before = u.axes[axis]._size;
  if (!values) return before || 48;
  u.ctx.font = u.axes[axis].font[0]; // the font as uPlot scales it for the canvas
  const widest = values.reduce((w, v) => Math.max(w, u.ctx.measureText(String(v)).width), 0);
  const size = Math.ceil(widest / devicePixelRatio) + 16;
  return cycle > 1 && before ? Math.max(before, size) : size;
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
    this.traces = []; // {id, value: its column, band: [column of value − h, of value + h] | null}
    this.index = new Map(); // trace id -> its entry in this.traces
    this.x = [];
    this.ys = []; // the columns: every trace's values and its band's edges
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
  newColumn() {
    this.ys.push(new Array(this.x.length).fill(null));
    this.rebuild = true;
    return this.ys.length - 1;
  }
  add(trace, points) {
    let entry = this.index.get(trace);
    if (entry === undefined) {
      entry = { id: trace, value: this.newColumn(), band: null };
      this.index.set(trace, entry);
      this.traces.push(entry);
    }
    let last = this.last.has(trace) ? this.last.get(trace) : -Infinity;
    for (const [t, y, h] of points) {
      if (t <= last) continue; // already drawn (a hello and a frame may overlap)
      const k = this.column(t);
      this.ys[entry.value][k] = y;
      const known = halfWidth(y, h);
      if (known && !entry.band) entry.band = [this.newColumn(), this.newColumn()];
      if (entry.band) {
        this.ys[entry.band[0]][k] = known ? y - h : y;
        this.ys[entry.band[1]][k] = known ? y + h : y;
      }
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
  data() {
    // uPlot's data: the x column, each band's upper and lower edges, then the traces' values
    const ys = this.ys;
    return [this.x, ...this.banded().flatMap((e) => [ys[e.band[1]], ys[e.band[0]]]),
      ...this.traces.map((e) => ys[e.value])];
  }
  banded() { return this.traces.filter((e) => e.band); }
  flush() {
    if (!this.dirty && !this.rebuild) return;
    // uPlot reads the arrays themselves: they change only between its redraws, in add()
    const data = this.data();
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
    const series = [{ label: "t" }], bands = [];
    for (const entry of this.banded()) {
      // the band's edges: not stroked, not in the y range (a wide interval does not squash
      // the estimates); uPlot fills between them, clipped to the plot
      const look = this.describe(entry.id);
      const edge = { width: 0, auto: false, spanGaps: true, points: { show: false } };
      series.push({ ...edge, label: `${look.name} + 95 %` }, { ...edge, label: `${look.name} − 95 %` });
      bands.push({ series: [series.length - 2, series.length - 1], fill: faded(look.colour) });
    }
    for (const entry of this.traces) {
      const look = this.describe(entry.id);
      series.push({ label: look.name, stroke: look.colour, width: look.width || 1.6,
        dash: DASHES[look.dash || "solid"], spanGaps: true, points: { show: false } });
    }
    this.plot = new uPlot({
      ...this.size(),
      legend: { show: false },
      scales: { x: { time: false }, y: { range: (u, min, max) => this.yRange(u, min, max) } },
      cursor: { drag: { x: true, y: false }, points: { show: false } },
      axes: [
        { ...AXIS, label: "t (s)", labelSize: 16, labelFont: AXIS.font, size: 30 },
        { ...AXIS, size: labelWidth, values: tickLabels },
      ],
      series,
      bands,
      hooks: { draw: [(u) => drawSwitchLines(u, this.switches)] },
    }, data, this.div);
    if (range) this.plot.setScale("x", { min: range[0], max: range[1] });
  }
  yRange(u, min, max) {
    // the lines' range (uPlot's min, max), widened to each band's newest edges within the x range
    let lo = min, hi = max;
    const end = u.scales.x.max, x = this.x;
    for (const entry of this.banded()) {
      const lower = this.ys[entry.band[0]], upper = this.ys[entry.band[1]];
      for (let k = x.length - 1; k >= 0; k--) {
        if ((end != null && x[k] > end) || lower[k] === null) continue;
        lo = lo === null ? lower[k] : Math.min(lo, lower[k]);
        hi = hi === null ? upper[k] : Math.max(hi, upper[k]);
        break;
      }
    }
    return lo === null || hi === null ? [null, null] : uPlot.rangeNum(lo, hi, 0.1, true);
  }
  setSwitches(switches) {
    if (JSON.stringify(switches) === JSON.stringify(this.switches)) return;
    this.switches = switches;
    if (this.plot) this.plot.redraw(false, false);
  }
  lines() {
    // [{name, x, y, h}] per trace: its points, in time order, and their 95 % half-widths
    // (null where it has none)
    return this.traces.map((entry) => {
      const x = [], y = [], h = [], values = this.ys[entry.value];
      const upper = entry.band ? this.ys[entry.band[1]] : null;
      values.forEach((value, k) => {
        if (value === null) return;
        x.push(this.x[k]);
        y.push(value);
        h.push(upper && upper[k] !== null && upper[k] > value ? upper[k] - value : null);
      });
      return { name: this.describe(entry.id).name, x, y, h };
    });
  }
  bands() {
    // [{name, x, lower, upper}] per band drawn: its edges where its trace has points
    return this.banded().map((entry) => {
      const x = [], lower = [], upper = [], lo = this.ys[entry.band[0]], hi = this.ys[entry.band[1]];
      lo.forEach((value, k) => {
        if (value === null) return;
        x.push(this.x[k]); lower.push(value); upper.push(hi[k]);
      });
      return { name: this.describe(entry.id).name, x, lower, upper };
    });
  }
  visible() {
    // [trace name, t, value, 95 % half-width or ""] of the points inside the current x range
    const scale = this.plot ? this.plot.scales.x : null;
    const zoomed = this.zoomed();
    const rows = [];
    for (const line of this.lines()) {
      line.x.forEach((t, k) => {
        if (zoomed && (t < scale.min || t > scale.max)) return;
        rows.push([line.name, t, line.y[k], line.h[k] === null ? "" : line.h[k]]);
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
function contactTrace(trace) {
  // ctc/ROBOT and ctc/ROBOT/truth: robot i's distance from its contact to the COM
  const [, who, truth] = trace.split("/");
  const robot = Number(who);
  if (truth) return { name: `‖pC − pC${robot}‖ (truth)`, colour: colour(robot), dash: "dot", width: 1 };
  return { name: `‖p̂C − pC${robot}‖ robot ${robot}`, colour: colour(robot), dash: dash(robot) };
}

// The estimated scalars' charts come with the hello (declare()), before these, in its order.
const charts = {
  edge: new TimeChart("chart-edge", "edge", edgeTrace),
  ctc: new TimeChart("chart-ctc", "ctc", contactTrace),
  omega: new TimeChart("chart-omega", "omega", robotTrace("ω")),
};

// ------------------------------------------------------------------------ the page's state
const heft = {
  scene: null, epoch: null, paused: false, frames: 0, receipts: [], charts: charts, scalars: [],
  views: {}, // the xy views, by name
  lastShape: "", wake: null, socket: null,
  chartMs: [], sceneMs: [], // how long each redraw took (ms), the newest RECEIPTS
};
window.heft = heft;

// The estimated scalars the hello declares: a chart each (a panel before the edges' chart, in
// the declared order) and the table's columns.
function declare(scalars) {
  const known = heft.scalars.map((s) => s.key).join(",");
  if (!Array.isArray(scalars) || scalars.map((s) => s.key).join(",") === known) return;
  heft.scalars = scalars;
  const before = document.getElementById("chart-edge").parentElement;
  for (const s of scalars) {
    if (charts[s.key]) continue;
    const panel = document.createElement("div");
    panel.className = "panel";
    const heading = document.createElement("h2");
    const unit = document.createElement("span");
    unit.className = "unit";
    unit.textContent = s.unit;
    heading.append(`${s.title} ${s.symbol} `, unit);
    const chart = document.createElement("div");
    chart.id = `chart-${s.key}`;
    chart.className = "chart";
    panel.append(heading, chart);
    before.before(panel);
    charts[s.key] = new TimeChart(chart.id, s.key, robotTrace(s.symbol));
    addChartJob(s.key, charts[s.key]);
  }
}

function takePoints(points) {
  for (const [trace, list] of Object.entries(points)) {
    const chart = charts[trace.split("/")[0]];
    if (chart) chart.add(trace, list);
  }
}

function markSwitches(scene) {
  const switches = Object.entries(scene.switches || {})
    .filter(([phase]) => phase !== "excite")
    .map(([phase, t]) => [t, PHASE_COLOURS[phase] || "#888"]);
  for (const chart of Object.values(charts)) chart.setSwitches(switches);
}

// ------------------------------------------------------------------------ xy views
// The phase timeline, the top view and the graph are uPlot charts too, in its xy mode (mode 2:
// each series has its own x and y arrays). Every segment, outline, arrow and link is a line
// series, every contact, COM and node a series of points, and a draw hook writes the labels.
// (As Plotly's SVG, these three views took p50 43-96 ms a redraw in heft bench --dashboard.)
const NO_LINE = () => null;
const EVERY_POINT = (u, i) => u.data[i][0].map((_, k) => k);

class XYView {
  // options: square (a unit as long on both axes), axes (show them), zoom (drag to zoom,
  // double-click to reset), xLabel, splits and ticks (the y axis' values and their labels),
  // before (a draw hook run before the labels). show() takes the series' looks, their data,
  // the extent to show and the labels: [x, y, text, colour, font, dy (px), background].
  constructor(id, options) {
    this.div = document.getElementById(id);
    this.options = options;
    this.plot = null;
    this.shape = "";
    this.series = []; // [{name, stroke, width, dash, points: {size, fill, stroke, width}}]
    this.data = []; // [[xs, ys]] per series
    this.extent = { x: [0, 1], y: [0, 1] };
    this.auto = null; // the ranges last chosen by range(), to tell a zoom from them
    this.labels = [];
    new ResizeObserver(() => { if (this.plot) this.plot.setSize(this.size()); }).observe(this.div);
  }
  size() {
    return { width: Math.max(80, this.div.clientWidth), height: Math.max(80, this.div.clientHeight) };
  }
  show(series, data, extent, labels) {
    if (!series.length) return; // uPlot's xy mode needs a series
    const zoomed = this.zoomed();
    this.series = series; this.data = data; this.extent = extent; this.labels = labels || [];
    const shape = JSON.stringify(series);
    if (!this.plot || shape !== this.shape) {
      this.shape = shape;
      this.build();
    } else {
      this.plot.batch(() => this.plot.setData([null, ...data], !zoomed));
    }
  }
  zoomed() {
    if (!this.plot || !this.auto || !this.options.zoom) return false;
    const { x, y } = this.plot.scales;
    const off = (a, b) => Math.abs(a - b) > 1e-9 * Math.max(1, Math.abs(b));
    return off(x.min, this.auto.x[0]) || off(x.max, this.auto.x[1])
      || off(y.min, this.auto.y[0]) || off(y.max, this.auto.y[1]);
  }
  range(axis) {
    // the extent, widened so that a metre is as long on both axes when square
    let [x0, x1] = this.extent.x, [y0, y1] = this.extent.y;
    if (this.options.square) {
      const box = this.plot ? this.plot.bbox : null;
      const w = box && box.width ? box.width : this.div.clientWidth;
      const h = box && box.height ? box.height : this.div.clientHeight;
      const per = Math.max((x1 - x0) / Math.max(w, 1), (y1 - y0) / Math.max(h, 1));
      const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
      [x0, x1] = [cx - (per * w) / 2, cx + (per * w) / 2];
      [y0, y1] = [cy - (per * h) / 2, cy + (per * h) / 2];
    }
    this.auto = Object.assign(this.auto || {}, { x: [x0, x1], y: [y0, y1] });
    return axis === "x" ? [x0, x1] : [y0, y1];
  }
  build() {
    const zoom = this.options.zoom;
    const range = zoom && this.plot && this.zoomed()
      ? { x: [this.plot.scales.x.min, this.plot.scales.x.max], y: [this.plot.scales.y.min, this.plot.scales.y.max] }
      : null;
    if (this.plot) this.plot.destroy();
    this.auto = null;
    const series = [{}];
    for (const look of this.series) {
      const points = look.points;
      series.push({
        label: look.name, stroke: look.stroke, width: look.width || 1.5, dash: look.dash || null,
        paths: points ? NO_LINE : undefined,
        points: points
          ? { show: false, filter: EVERY_POINT, size: points.size, width: points.width || 1,
            fill: points.fill, stroke: points.stroke }
          : { show: false },
      });
    }
    const axes = this.options.axes
      ? [{ ...AXIS, size: 24, label: this.options.xLabel, labelSize: this.options.xLabel ? 16 : 0,
        labelFont: AXIS.font, values: tickLabels },
      { ...AXIS, size: this.options.ticks ? 64 : labelWidth, values: this.options.ticks || tickLabels,
        splits: this.options.splits }]
      : [{ show: false }, { show: false }];
    this.plot = new uPlot({
      ...this.size(),
      mode: 2,
      legend: { show: false },
      cursor: zoom ? { drag: { x: true, y: true, uni: 20 }, points: { show: false } } : { show: false },
      scales: {
        x: { time: false, range: () => this.range("x") },
        y: { range: () => this.range("y") },
      },
      axes,
      series,
      hooks: { draw: [(u) => this.drawLabels(u)] },
    }, [null, ...this.data], this.div);
    if (range) {
      this.plot.batch(() => {
        this.plot.setScale("x", { min: range.x[0], max: range.x[1] });
        this.plot.setScale("y", { min: range.y[0], max: range.y[1] });
      });
    }
  }
  drawLabels(u) {
    if (this.options.before) this.options.before(u);
    const ctx = u.ctx;
    ctx.save();
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    for (const [x, y, text, colour, font, dy, background] of this.labels) {
      ctx.font = font || `${Math.round(11 * devicePixelRatio)}px system-ui, sans-serif`;
      const px = u.valToPos(x, "x", true), py = u.valToPos(y, "y", true) + (dy || 0) * devicePixelRatio;
      if (background) {
        const w = ctx.measureText(text).width + 6 * devicePixelRatio, h = 15 * devicePixelRatio;
        ctx.fillStyle = background;
        ctx.fillRect(px - w / 2, py - h / 2, w, h);
      }
      ctx.fillStyle = colour;
      ctx.fillText(text, px, py);
    }
    ctx.restore();
  }
  lines() {
    // [{name, x, y}] per series, as drawn
    return this.series.map((look, i) => ({ name: look.name, x: this.data[i][0], y: this.data[i][1] }));
  }
}

function widen([lo, hi], margin) {
  const pad = Math.max(hi - lo, 1e-3) * margin;
  return [lo - pad, hi + pad];
}
function extentOf(data) {
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const [xs, ys] of data) {
    xs.forEach((x, k) => {
      if (x === null || ys[k] === null) return;
      x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, ys[k]); y1 = Math.max(y1, ys[k]);
    });
  }
  return x0 <= x1 ? { x: [x0, x1], y: [y0, y1] } : { x: [-1, 1], y: [-1, 1] };
}
function bold(px) { return `bold ${Math.round(px * devicePixelRatio)}px system-ui, sans-serif`; }

// ------------------------------------------------------------------------ the phase timeline
// A thick line per robot and phase segment, robot 1 on top (y = −robot).
const timeline = new XYView("chart-phases", {
  axes: true, zoom: true, xLabel: "t (s)",
  splits: () => Array.from({ length: heft.timelineRobots || 0 }, (_, k) => -(k + 1)),
  ticks: (u, splits) => splits.map((v) => `robot ${-v}`),
  before: (u) => drawSwitchLines(u, heft.timelineSwitches || []),
});

function drawTimeline(scene) {
  const now = scene.t;
  const robots = Object.keys(scene.robots).map(Number).sort((a, b) => a - b);
  const n = Math.max(scene.n || 0, robots.length, 1);
  heft.timelineRobots = n;
  const width = Math.max(3, Math.min(14, (0.6 * timeline.div.clientHeight) / n));
  const series = [], data = [];
  for (const robot of robots) {
    const segments = scene.robots[robot].segments;
    segments.forEach(([phase, start], k) => {
      const end = k + 1 < segments.length ? segments[k + 1][1] : Math.max(now, start);
      series.push({ name: `${phase} robot ${robot}`, stroke: PHASE_COLOURS[phase] || "#888", width });
      data.push([[start, Math.max(end, start + now * 0.002 + 1e-3)], [-robot, -robot]]);
    });
  }
  heft.timelineSwitches = Object.entries(scene.switches || {})
    .filter(([phase]) => phase !== "excite").map(([phase, t]) => [t, PHASE_COLOURS[phase] || "#888"]);
  put("phase-legend", "innerHTML", scene.phases
    .map((p) => `<span style="color:${PHASE_COLOURS[p]}">■</span> ${p}`).join(" "));
  timeline.show(series, data, { x: [0, Math.max(now, 1e-3)], y: [-n - 0.6, -0.4] });
}
function drawSwitchLines(u, switches) {
  // the team's phase switches as dotted vertical lines
  const ctx = u.ctx, { left, top, width, height } = u.bbox;
  ctx.save();
  ctx.lineWidth = devicePixelRatio;
  ctx.setLineDash([2 * devicePixelRatio, 3 * devicePixelRatio]);
  for (const [t, colour] of switches) {
    const x = Math.round(u.valToPos(t, "x", true));
    if (x < left || x > left + width) continue;
    ctx.strokeStyle = colour;
    ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
  }
  ctx.restore();
}

// ------------------------------------------------------------------------ the top view
const topView = new XYView("top", { square: true, axes: true, zoom: true });

function drawTop(scene) {
  const top = scene.top;
  put("top-source", "textContent", top
    ? (top.source === "truth" ? "world frame, truth and estimates" : "about p_G, estimates only") : "");
  if (!top) return;
  const series = [], data = [], labels = [];
  if (top.outline) {
    const xs = top.outline.map((p) => p[0]), ys = top.outline.map((p) => p[1]);
    xs.push(xs[0]); ys.push(ys[0]);
    series.push({ name: "load", stroke: "#8a93a3", width: 1.5 });
    data.push([xs, ys]);
  }
  // The commanded forces as arrows (a shaft, then the head's two strokes from the tip), the
  // largest a quarter of the load's size: the forces' directions and ratios, not newtons.
  const contacts = top.contacts.map((p, k) => ({ p, robot: k + 1 })).filter((c) => c.p);
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
    series.push({ name: `force ${robot}`, stroke: colour(Number(robot)), width: 2 });
    data.push([[c[0], tip[0], left[0], tip[0], right[0]], [c[1], tip[1], left[1], tip[1], right[1]]]);
  }
  for (const c of contacts) {
    series.push({ name: `contact ${c.robot}`, points: { size: 11, fill: colour(c.robot), stroke: "#000" } });
    data.push([[c.p[0]], [c.p[1]]]);
    labels.push([c.p[0], c.p[1], String(c.robot), "#d8dde6", null, -12]);
  }
  for (const [robot, p] of Object.entries(top.com_estimates || {})) {
    series.push({ name: `COM estimate ${robot}`,
      points: { size: 10, width: 2, fill: "#1a1d24", stroke: colour(Number(robot)) } });
    data.push([[p[0]], [p[1]]]);
  }
  if (top.com) {
    series.push({ name: "COM (truth)", points: { size: 6, fill: TRUTH_COLOUR, stroke: TRUTH_COLOUR } });
    data.push([[top.com[0]], [top.com[1]]]);
    labels.push([top.com[0], top.com[1], "C", TRUTH_COLOUR, null, 11]);
  }
  const extent = extentOf(data); // the ellipses do not set it: a wide one would hide the load
  for (const [robot, axes] of Object.entries(top.com_ellipses || {})) {
    const p = (top.com_estimates || {})[robot];
    const xy = p && ellipse(p, axes);
    if (!xy) continue;
    series.push({ name: `COM 95 % ellipse ${robot}`, stroke: colour(Number(robot)), width: 1, dash: [3, 3] });
    data.push(xy);
  }
  topView.show(series, data, { x: widen(extent.x, 0.08), y: widen(extent.y, 0.08) }, labels);
}

// The 95 % ellipse [major, minor semi-axis (m), angle of the major axis] about p, as a closed
// line; null unless its numbers can be one.
function ellipse(p, axes) {
  if (!Array.isArray(axes) || axes.length !== 3 || !axes.every(Number.isFinite)
    || axes[0] < 0 || axes[1] < 0) return null;
  const [a, b, angle] = axes, c = Math.cos(angle), s = Math.sin(angle), xs = [], ys = [];
  for (let k = 0; k <= 48; k++) {
    const u = (2 * Math.PI * k) / 48, ex = a * Math.cos(u), ey = b * Math.sin(u);
    xs.push(p[0] + c * ex - s * ey);
    ys.push(p[1] + s * ex + c * ey);
  }
  return [xs, ys];
}

// ------------------------------------------------------------------------ the graph
const graph = new XYView("graph", { square: true });

function drawGraph(scene) {
  const n = scene.n || Object.keys(scene.robots).length;
  if (!n) return;
  const at = (i) => [Math.cos(Math.PI / 2 - (2 * Math.PI * (i - 1)) / n),
    Math.sin(Math.PI / 2 - (2 * Math.PI * (i - 1)) / n)];
  const series = [], data = [], labels = [];
  for (const link of scene.links) {
    const [i, j] = link.edge, a = at(i), b = at(j);
    series.push({ name: `link ${i}-${j}: ${link.health}`, stroke: HEALTH_COLOURS[link.health] || "#888", width: 3 });
    data.push([[a[0], b[0]], [a[1], b[1]]]);
    if (scene.links.length <= 12) {
      labels.push([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2,
        `${link.age_s === null ? "–" : link.age_s.toFixed(2)} s · ${link.rate_hz}/s`,
        HEALTH_COLOURS[link.health] || "#888", `${Math.round(10 * devicePixelRatio)}px system-ui, sans-serif`,
        0, "rgba(17,19,24,0.85)"]);
    }
  }
  const lost = new Set();
  for (const alarm of scene.alarms) {
    const m = /robot\(s\) \[([\d, ]+)\] lost/.exec(alarm.text);
    if (m) m[1].split(",").forEach((r) => lost.add(Number(r)));
  }
  for (let i = 1; i <= n; i++) {
    const p = at(i);
    series.push({ name: `robot ${i}`,
      points: { size: 24, width: 3, fill: colour(i), stroke: lost.has(i) ? "#f85149" : "#0c0e12" } });
    data.push([[p[0]], [p[1]]]);
    labels.push([p[0], p[1], String(i), "#0c0e12", bold(11)]);
  }
  graph.show(series, data, { x: [-1.3, 1.3], y: [-1.2, 1.2] }, labels);
}
heft.views = { timeline, top: topView, graph };

// ------------------------------------------------------------------------ the DOM
// The page's text is written only when it changed: every write makes the browser restyle and
// lay out again, and the header is refreshed at every animation frame.
const written = new Map(); // "id.property" -> the value last written

function put(id, property, value) {
  const key = `${id}.${property}`;
  if (written.get(key) === value) return;
  written.set(key, value);
  const element = document.getElementById(id);
  if (property === "background") element.style.background = value;
  else element[property] = value;
}

// ------------------------------------------------------------------------ the table
// Beside each value with a published uncertainty, "± h": its 95 % interval's half-width, in the
// value's unit (kg, kg m²; mm for p̂_C − p_Ci and ẑ_ij, along the 95 % ellipse's longest axis,
// as heft run's "95 % intervals" table); beside its error, ✓ when the truth lies inside the
// interval (the ellipse), ✗ when it does not.
function plain(symbol) { return symbol.normalize("NFD").replace(/\u0302/g, ""); }
function plusMinus(interval, factor, digits) {
  const h = Array.isArray(interval) ? interval[0] : null;
  return typeof h === "number" && Number.isFinite(h) && h >= 0
    ? `<span class="pm" title="95 % interval">±${fmt(h * factor, digits)}</span>` : "";
}
function verdict(interval) {
  const inside = Array.isArray(interval) ? interval[1] : null;
  if (inside === true) return ` <span class="inside" title="the truth lies inside the 95 % interval">✓</span>`;
  if (inside === false) return ` <span class="outside" title="the truth lies outside the 95 % interval">✗</span>`;
  return "";
}
function drawTable(scene) {
  const table = scene.table, scalars = heft.scalars;
  put("table-title", "innerHTML", table.final
    ? `<span class="final">final</span> estimates against truth (t = ${fmt(table.t, 2)} s)`
    : "latest estimates against truth");
  const judged = scalars.filter((s) => s.error);
  const rows = [`<tr><th>robot</th><th>phase</th>`
    + scalars.map((s) => `<th>${s.symbol} ${s.unit}</th>`).join("")
    + judged.map((s) => {
      const [name, hat] = [plain(s.symbol), s.symbol];
      return s.relative ? `<th title="|${hat} − ${name}| / ${name}">${name} %</th>`
        : `<th title="|${hat} − ${name}|">${name} ${s.unit}</th>`;
    }).join("")
    + `<th title="‖(p̂_C − p_Ci) − (p_C − p_Ci)‖">c mm</th><th title="max_j ‖ẑ_ij − z_ij‖">z mm</th></tr>`];
  for (const [robot, row] of Object.entries(table.robots)) {
    const e = row.errors || {}, intervals = row.intervals || {};
    const c = row.contact_to_com ? `p̂_C − p_C${robot} = (${fmt(row.contact_to_com[0], 4)}, ${fmt(row.contact_to_com[1], 4)}) m` : "";
    rows.push(`<tr title="${c}"><td><span class="swatch" style="background:${colour(Number(robot))}"></span>${robot}</td>`
      + `<td style="color:${PHASE_COLOURS[row.phase] || "inherit"}"`
      + ` title="probe score: ${row.change_score == null ? "–" : fmt(row.change_score, 1) + " σ"}">`
      + `${row.phase}${row.load_changes ? ` <span class="restarts">(load changes: ${row.load_changes})</span>` : ""}`
      + `${row.rejoins ? ` <span class="restarts">(begun again: rejoin ${row.rejoins})</span>` : ""}</td>`
      + scalars.map((s) => `<td>${fmt(row[s.key], s.digits)}${plusMinus(intervals[s.key], 1, s.digits)}</td>`).join("")
      + judged.map((s) => `<td>${fmt(scaled(e[s.error], s.relative ? 100 : 1), 3)}${verdict(intervals[s.key])}</td>`).join("")
      + `<td>${fmt(scaled(e.contact_to_com_m, 1000), 2)}${verdict(intervals.contact_to_com)}`
      + `${plusMinus(intervals.contact_to_com, 1000, 2)}</td>`
      + `<td>${fmt(scaled(e.relative_positions_m, 1000), 2)}${verdict(intervals.relative_positions)}`
      + `${plusMinus(intervals.relative_positions, 1000, 2)}</td></tr>`);
  }
  if (table.truth) {
    rows.push(`<tr class="truth"><td>truth</td><td></td>`
      + scalars.map((s) => `<td>${fmt(table.truth[s.key], s.digits)}</td>`).join("")
      + `<td colspan="${judged.length + 2}"></td></tr>`);
  }
  put("table", "innerHTML", rows.join(""));
}

// ------------------------------------------------------------------------ header and alarms
function drawHeader(scene, source) {
  put("team", "textContent", scene.team ? `team ${scene.team}` : "");
  put("clock", "textContent", `t = ${fmt(scene.t, 2)} s`);
  if (source.mode === "replay") {
    const speed = source.speed === 0 ? "max" : `${source.speed}×`;
    put("source", "textContent", `REPLAY ${speed}${source.paused ? " · paused" : ""}`
      + `${source.finished ? " · end" : ""} · ${fmt(source.position_s, 1)} s`);
    put("source", "className", "badge replay");
  } else {
    put("source", "textContent", "LIVE");
    put("source", "className", "badge live");
  }
  put("replay-controls", "hidden", !source.recording);
  put("replay-toggle", "textContent", source.paused ? "▶" : "❚❚");
  const phases = {};
  for (const [robot, view] of Object.entries(scene.robots)) {
    if (view.phase) (phases[view.phase] = phases[view.phase] || []).push(robot);
  }
  const names = Object.keys(phases);
  put("team-phase", "textContent",
    names.length === 1 ? names[0] : names.map((p) => `${p} ${phases[p].join(",")}`).join(" · ") || "–");
  put("team-phase", "background", names.length === 1 ? PHASE_COLOURS[names[0]] + "55" : "");
  put("alarms", "hidden", !scene.alarms.length);
  put("alarms", "innerHTML", scene.alarms.map((a) => `<div class="alarm ${a.level}">⚠ ${a.text}</div>`).join(""));
}

// ------------------------------------------------------------------------ drawing
// The drawing jobs that are due run in an animation frame, the most overdue first, until the
// frame has taken FRAME_MS: a page never blocks for much longer than its slowest job (so
// frames from the server keep arriving on time), and jobs due together share a frame (each
// frame the browser lays out and paints costs as much as a chart's redraw). Each job waits at
// least BUDGET times its own last duration before it runs again (a big team's charts redraw
// less often rather than starve the page).
const BUDGET = 4;
const FRAME_MS = 12;
const jobs = [
  { name: "top", every: SCENE_EVERY_MS, run: () => drawTop(heft.scene) },
  { name: "table", every: SCENE_EVERY_MS, run: () => drawTable(heft.scene) },
  { name: "switches", every: SLOW_EVERY_MS, run: () => markSwitches(heft.scene) },
  { name: "timeline", every: SLOW_EVERY_MS, changes: true, run: () => drawTimeline(heft.scene) },
  { name: "graph", every: SLOW_EVERY_MS, changes: true, run: () => drawGraph(heft.scene) },
];
for (const job of jobs) { job.last = -Infinity; job.took = 0; }
function addChartJob(name, chart) {
  jobs.push({ name, every: CHART_EVERY_MS, chart: true, run: () => chart.flush(), last: -Infinity, took: 0 });
}
for (const [name, chart] of Object.entries(charts)) addChartJob(name, chart);

function sceneShape(scene) {
  return JSON.stringify([scene.switches, scene.links.map((l) => l.health),
    Object.values(scene.robots).map((r) => r.segments.length), scene.alarms.length]);
}

function render(force) {
  const frame = performance.now();
  if (!heft.scene) return;
  drawHeader(heft.scene, heft.source);
  if (heft.paused) return;
  const shape = sceneShape(heft.scene);
  const changed = shape !== heft.lastShape;
  heft.lastShape = shape;
  const dueAt = (job) => job.last + Math.max(job.every, BUDGET * job.took);
  const due = [];
  for (const job of jobs) {
    if (force || (changed && job.changes)) job.last = -Infinity;
    job.due = dueAt(job);
    if (job.due <= frame) due.push(job);
  }
  due.sort((a, b) => a.due - b.due);
  let ran = 0;
  for (const job of due) {
    const started = performance.now();
    if (ran > 0 && started - frame + job.took > FRAME_MS) break;
    job.run();
    job.took = performance.now() - started;
    job.last = started;
    (job.chart ? heft.chartMs : heft.sceneMs).push(job.took);
    ran += 1;
  }
  if (ran < due.length) {
    schedule();
  } else {
    const wait = Math.min(...jobs.map(dueAt)) - performance.now();
    clearTimeout(heft.wake);
    heft.wake = setTimeout(schedule, Math.max(0, wait));
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
    declare(message.scalars);
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
    put("source", "textContent", "disconnected: retrying");
    put("source", "className", "badge down");
    setTimeout(connect, 1000);
  };
}

// ------------------------------------------------------------------------ controls
function exportCsv() {
  const lines = ["chart,trace,t_s,value,half_95"];
  for (const [name, chart] of Object.entries(charts)) {
    for (const [trace, t, value, h] of chart.visible()) lines.push(`${name},"${trace}",${t},${value},${h}`);
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
