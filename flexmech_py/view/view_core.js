/* flexmech view, part 1 of 3 (page.PARTS): helpers, colours, the chart on a canvas.
   The three parts run inside one function scope (template.html); no request leaves the page (its
   Content-Security-Policy forbids them); nothing here computes physics: every number comes from the
   result's files (flexmech_py/view/*_data.py). */
const DATA = JSON.parse(document.getElementById("flexmech-data").textContent);
const $ = (id) => document.getElementById(id);
const DPR = () => window.devicePixelRatio || 1;
const PT = 96 / 72;                       // CSS pixels per point (the glyph table's sizes are in points)
const SUB = 8;                            // sub-segments per element of a flexible link (cubic Hermite)
const PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"];
const MU_COLOURS = { "real+": "#d62728", "real-": "#9467bd", complex: "#ff7f0e", stable: "#1f4fb4" };
const state = { ready: false, kind: DATA.kind, draws: 0 };
window.flexmechView = state;

function el(tag, attrs, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v; else if (k === "text") e.textContent = v; else e.setAttribute(k, v);
  }
  for (const k of kids) e.append(k);
  return e;
}

function decode(s, Type) {
  if (!s) return null;
  const bin = atob(s);
  const u = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) u[i] = bin.charCodeAt(i);
  return new Type(u.buffer);
}

function fmt(v, digits) {
  digits = digits || 4;
  if (v === null || v === undefined || !isFinite(v)) return "–";
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(digits - 1).replace("e+", "e");
  return String(parseFloat(v.toPrecision(digits)));
}
const unitText = (u) => (u && u !== "1" && u !== "-" ? " " + u : "");
const pct = (f) => (f >= 0.1 ? fmt(100 * f, 3) : fmt(100 * f, 2)) + " %";

// ------------------------------------------------------------------ colours
const STOPS = [[33, 102, 172], [103, 169, 207], [209, 229, 240], [247, 247, 247], [253, 219, 199],
  [239, 138, 98], [178, 24, 43]];              // diverging: compression blue, 0 white, tension red
function divColour(s) {
  if (!isFinite(s)) return "#999";
  s = Math.max(-1, Math.min(1, s));
  const f = ((s + 1) / 2) * (STOPS.length - 1);
  const i = Math.min(Math.floor(f), STOPS.length - 2), r = f - i, a = STOPS[i], b = STOPS[i + 1];
  return "rgb(" + [0, 1, 2].map((k) => Math.round(a[k] + (b[k] - a[k]) * r)).join(",") + ")";
}

function niceTicks(lo, hi, n) {
  if (!(hi > lo)) { hi = lo + 1; }
  const raw = (hi - lo) / Math.max(n, 1), p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * p).find((s) => s >= raw) || 10 * p;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(Math.abs(v) < 1e-12 * step ? 0 : v);
  return out;
}

function search(arr, x) {                      // index of the sample of sorted arr nearest to x
  let lo = 0, hi = arr.length - 1;
  if (hi < 0) return -1;
  while (hi - lo > 1) { const m = (lo + hi) >> 1; if (arr[m] <= x) lo = m; else hi = m; }
  return Math.abs(arr[hi] - x) < Math.abs(x - arr[lo]) ? hi : lo;
}

function fitCanvas(c) {
  const w = Math.max(1, Math.round(c.clientWidth * DPR())), h = Math.max(1, Math.round(c.clientHeight * DPR()));
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; return true; }
  return false;
}

const tip = el("div", { class: "tip", id: "tip" });
document.body.append(tip);
function showTip(evt, html) {
  if (!html) { tip.style.display = "none"; return; }
  tip.innerHTML = html;
  tip.style.display = "block";
  const w = tip.offsetWidth;
  tip.style.left = (evt.clientX + 14 + w > window.innerWidth ? evt.clientX - w - 10 : evt.clientX + 14) + "px";
  tip.style.top = (evt.clientY + 12) + "px";
}
const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));

// ------------------------------------------------------------------ chart
/* A chart on a canvas: line, point and band series over x, shaded x spans, horizontal lines, marks
   on the x axis; a cursor (setCursor) and a hover read-out; the static part is drawn once. */
class Chart {
  constructor(canvas, o) {
    this.c = canvas; this.o = o; this.cursor = null; this.hover = null;
    this.base = document.createElement("canvas");
    this.m = { l: 58, r: 10, t: o.title ? 18 : 8, b: 30 };
    canvas.addEventListener("mousemove", (e) => this.move(e));
    canvas.addEventListener("mouseleave", () => { this.hover = null; showTip(null); this.render(); });
    canvas.addEventListener("click", (e) => { if (o.onPick) o.onPick(this.xOf(this.px(e))); });
    this.yr = this.yRange();
  }
  yRange() {
    const o = this.o;
    if (o.ymin !== undefined && o.ymax !== undefined) return [o.ymin, o.ymax];
    let lo = Infinity, hi = -Infinity;
    const take = (v) => { if (isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); } };
    for (const s of o.series) {
      if (s.kind === "band") { s.lo.forEach(take); s.hi.forEach(take); } else if (!s.noRange) s.y.forEach(take);
    }
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi === lo) { const d = Math.abs(hi) || 1; lo -= 0.5 * d; hi += 0.5 * d; }
    const pad = 0.06 * (hi - lo);
    return [o.ymin !== undefined ? o.ymin : lo - pad, o.ymax !== undefined ? o.ymax : hi + pad];
  }
  fy(y) { const t = this.o.linthresh; return this.o.scale === "symlog" ? Math.sign(y) * Math.log10(1 + Math.abs(y) / t) : y; }
  px(e) { const r = this.c.getBoundingClientRect(); return e.clientX - r.left; }
  X(x) { const w = this.c.clientWidth; return this.m.l + (x - this.o.xmin) / (this.o.xmax - this.o.xmin) * (w - this.m.l - this.m.r); }
  xOf(px) { const w = this.c.clientWidth; return this.o.xmin + (px - this.m.l) / (w - this.m.l - this.m.r) * (this.o.xmax - this.o.xmin); }
  Y(y) {
    const h = this.c.clientHeight, a = this.fy(this.yr[0]), b = this.fy(this.yr[1]);
    return h - this.m.b - (this.fy(y) - a) / (b - a) * (h - this.m.t - this.m.b);
  }
  yTicks() {
    if (this.o.scale !== "symlog") return niceTicks(this.yr[0], this.yr[1], 4);
    const out = [0];
    for (let p = Math.ceil(Math.log10(this.o.linthresh)); p <= Math.log10(this.yr[1]); p++) out.push(Math.pow(10, p));
    for (let p = Math.ceil(Math.log10(this.o.linthresh)); p <= Math.log10(-this.yr[0]); p++) out.push(-Math.pow(10, p));
    return out.filter((v) => v >= this.yr[0] && v <= this.yr[1]);
  }
  draw() {
    const c = this.c;
    fitCanvas(c);
    this.base.width = c.width; this.base.height = c.height;
    const g = this.base.getContext("2d"), o = this.o, w = c.clientWidth, h = c.clientHeight, m = this.m;
    g.setTransform(DPR(), 0, 0, DPR(), 0, 0);
    g.clearRect(0, 0, w, h);
    g.font = "11px sans-serif";
    g.save();
    g.beginPath(); g.rect(m.l, m.t, w - m.l - m.r, h - m.t - m.b); g.clip();
    for (const s of o.spans || []) {
      g.fillStyle = s.colour; g.globalAlpha = s.alpha || 0.12;
      const a = this.X(s.lo), b = Math.max(this.X(s.hi), a + 2);
      g.fillRect(a, m.t, b - a, h - m.t - m.b);
      g.globalAlpha = 1;
      if (s.label) { g.fillStyle = s.text || s.colour; g.textAlign = s.align || "left"; g.fillText(s.label, s.align === "center" ? (a + b) / 2 : a + 3, m.t + 11 + 12 * (s.row || 0)); }
    }
    for (const hl of o.hbands || []) {
      g.fillStyle = hl.colour; g.globalAlpha = hl.alpha;
      const a = this.Y(hl.hi), b = this.Y(hl.lo);
      g.fillRect(m.l, a, w - m.l - m.r, b - a); g.globalAlpha = 1;
    }
    g.strokeStyle = "#eee"; g.lineWidth = 1;
    for (const v of this.yTicks()) { g.beginPath(); g.moveTo(m.l, this.Y(v)); g.lineTo(w - m.r, this.Y(v)); g.stroke(); }
    for (const s of o.series) this.drawSeries(g, s);
    for (const hl of o.hlines || []) {
      g.strokeStyle = hl.colour; g.setLineDash(hl.dash || [5, 4]); g.lineWidth = 1;
      g.beginPath(); g.moveTo(m.l, this.Y(hl.y)); g.lineTo(w - m.r, this.Y(hl.y)); g.stroke(); g.setLineDash([]);
    }
    for (const mk of o.marks || []) {
      const x = this.X(mk.x);
      g.fillStyle = mk.colour; g.beginPath(); g.moveTo(x - 5, m.t); g.lineTo(x + 5, m.t); g.lineTo(x, m.t + 8); g.closePath(); g.fill();
    }
    g.restore();
    g.strokeStyle = "#888"; g.strokeRect(m.l + 0.5, m.t + 0.5, w - m.l - m.r - 1, h - m.t - m.b - 1);
    g.fillStyle = "#333"; g.textAlign = "right"; g.textBaseline = "middle";
    let lastY = -Infinity;
    for (const v of this.yTicks().sort((a, b) => b - a)) {     // top down, none closer than 12 px
      const Y = this.Y(v);
      if (Y - lastY >= 12) { g.fillText(fmt(v, 3), m.l - 4, Y); lastY = Y; }
    }
    g.textAlign = "left"; g.fillStyle = "#888";
    for (const s of o.series) if (s.tag) { const i = s.x.length - 1, Y = this.Y(s.y[i]); if (Y > m.t + 6 && Y < h - m.b) g.fillText(s.tag, this.X(s.x[i]) - 22, Y - 6); }
    g.fillStyle = "#333";
    g.textAlign = "center"; g.textBaseline = "top";
    for (const v of niceTicks(o.xmin, o.xmax, Math.max(3, Math.floor((w - m.l) / 90)))) {
      g.fillText(fmt(v, 4), this.X(v), h - m.b + 3);
      g.beginPath(); g.moveTo(this.X(v), h - m.b); g.lineTo(this.X(v), h - m.b + 3); g.stroke();
    }
    g.fillText(o.xlabel || "", (m.l + w - m.r) / 2, h - 13);
    if (o.title) { g.textAlign = "left"; g.fillText(o.title, m.l, 3); }
    g.save(); g.translate(11, (m.t + h - m.b) / 2); g.rotate(-Math.PI / 2); g.textBaseline = "middle";
    g.fillText(o.ylabel || "", 0, 0); g.restore();
    this.render();
  }
  drawSeries(g, s) {
    if (s.kind === "band") {
      g.fillStyle = s.colour; g.globalAlpha = 0.35; g.beginPath();
      for (let i = 0; i < s.x.length; i++) g.lineTo(this.X(s.x[i]), this.Y(s.hi[i]));
      for (let i = s.x.length - 1; i >= 0; i--) g.lineTo(this.X(s.x[i]), this.Y(s.lo[i]));
      g.closePath(); g.fill(); g.globalAlpha = 1; return;
    }
    if (s.kind !== "points") {
      g.strokeStyle = s.colour; g.lineWidth = s.width || 1.4; g.setLineDash(s.dash || []);
      g.beginPath(); let pen = false;
      for (let i = 0; i < s.x.length; i++) {
        if (!isFinite(s.y[i])) { pen = false; continue; }
        const X = this.X(s.x[i]), Y = this.Y(s.y[i]);
        if (pen) g.lineTo(X, Y); else g.moveTo(X, Y);
        pen = true;
      }
      g.stroke(); g.setLineDash([]);
    }
    if (s.kind === "points" || s.markers) {
      for (let i = 0; i < s.x.length; i++) {
        if (!isFinite(s.y[i])) continue;
        g.fillStyle = s.colours ? s.colours[i] : s.colour;
        g.beginPath(); g.arc(this.X(s.x[i]), this.Y(s.y[i]), s.radius || 2.5, 0, 2 * Math.PI); g.fill();
      }
    }
  }
  render() {
    const c = this.c, g = c.getContext("2d"), m = this.m;
    g.setTransform(1, 0, 0, 1, 0, 0); g.clearRect(0, 0, c.width, c.height); g.drawImage(this.base, 0, 0);
    g.setTransform(DPR(), 0, 0, DPR(), 0, 0);
    const h = c.clientHeight;
    if (this.hover !== null) {
      g.strokeStyle = "#999"; g.setLineDash([3, 3]); g.beginPath();
      g.moveTo(this.X(this.hover), m.t); g.lineTo(this.X(this.hover), h - m.b); g.stroke(); g.setLineDash([]);
    }
    if (this.cursor !== null) {
      const X = this.X(this.cursor);
      g.strokeStyle = "#000"; g.lineWidth = 1.2; g.beginPath(); g.moveTo(X, m.t); g.lineTo(X, h - m.b); g.stroke();
      for (const s of this.o.series) {
        if (s.kind === "band" || s.kind === "points" || s.noCursor) continue;
        const i = search(s.x, this.cursor);
        if (i < 0 || !isFinite(s.y[i])) continue;
        g.fillStyle = s.colour; g.beginPath(); g.arc(this.X(s.x[i]), this.Y(s.y[i]), 3.2, 0, 2 * Math.PI); g.fill();
      }
    }
  }
  setCursor(x) { this.cursor = x; this.render(); }
  move(e) {
    const px = this.px(e), x = this.xOf(px);
    if (px < this.m.l || px > this.c.clientWidth - this.m.r) { this.hover = null; showTip(null); this.render(); return; }
    this.hover = x; this.render();
    const near = (this.o.marks || []).filter((mk) => Math.abs(this.X(mk.x) - px) <= 5);
    showTip(e, this.o.readout(x, near));
  }
}
