/* flexmech view: the page of one result, drawn on canvases from the data embedded in the page.
   No request leaves the page (its Content-Security-Policy forbids them); nothing here computes
   physics: every number comes from the result's files (flexmech_py/view/*_data.py). */
(function () {
  "use strict";
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

  // ------------------------------------------------------------------ mechanism
  /* The mechanism on a canvas: the rigid configuration dashed (the ghost), the deformed bodies (a
     flexible link's nodes joined by the cubic Hermite interpolation of its displacement and slope,
     coloured by a field along its length), the joints and the ground with the glyphs of
     flexmech_py.glyphs; wheel zooms, dragging pans, a double click fits the view again. */
  class Mechanism {
    constructor(canvas, d, field) {
      this.c = canvas; this.d = d; this.field = field; this.g = d.glyphs;
      const S = d.shapes;
      this.F = S.frames; this.P = S.points;
      this.key = decode(S.key, Float64Array); this.x = decode(S.x, Float32Array); this.dd = decode(S.d, Float32Array);
      this.rot = decode(S.rot, Float32Array); this.kappa = decode(S.kappa, Float32Array);
      this.frame = 0; this.amp = 1; this.view = null; this.zoom = 1; this.pan = [0, 0]; this.lines = [];
      this.interact();
    }
    bounds(amp) {
      let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
      const X = this.x, D = this.dd, n = this.F * this.P;
      for (let k = 0; k < n; k++) {
        for (const a of [0, amp, -amp]) {
          const px = X[2 * k] + a * D[2 * k], py = X[2 * k + 1] + a * D[2 * k + 1];
          if (px < x0) x0 = px; if (px > x1) x1 = px; if (py < y0) y0 = py; if (py > y1) y1 = py;
        }
      }
      for (const j of this.d.joints) if (j.ground) { x0 = Math.min(x0, j.ground[0]); x1 = Math.max(x1, j.ground[0]); y0 = Math.min(y0, j.ground[1]); y1 = Math.max(y1, j.ground[1]); }
      const pad = 0.08 * Math.max(x1 - x0, y1 - y0, 1e-9);
      return [x0 - pad, y0 - pad, x1 + pad, y1 + pad];
    }
    fit(amp) { this.view = this.bounds(amp); this.zoom = 1; this.pan = [0, 0]; }
    transform() {
      const w = this.c.clientWidth, h = this.c.clientHeight, [x0, y0, x1, y1] = this.view;
      const k = Math.min(w / (x1 - x0), h / (y1 - y0)) * this.zoom;
      const cx = (x0 + x1) / 2 + this.pan[0], cy = (y0 + y1) / 2 + this.pan[1];
      return { k, sx: (x) => w / 2 + (x - cx) * k, sy: (y) => h / 2 - (y - cy) * k, wx: (p) => cx + (p - w / 2) / k, wy: (p) => cy - (p - h / 2) / k };
    }
    pt(i, p, amp) { const k = (i * this.P + p) * 2; return [this.x[k] + amp * this.dd[k], this.x[k + 1] + amp * this.dd[k + 1]]; }
    /* one body's deformed line [[x, y, field]...] at frame i (amp: the magnification times the shape's factor) */
    line(b, i, amp, fieldOf) {
      const P = this.P, X = this.x, D = this.dd, R = this.rot, s0 = b.start, n = b.n;
      if (b.kind !== "flexible" || n < 2) {
        const out = [];
        for (let p = s0; p < s0 + n; p++) out.push(this.pt(i, p, amp).concat([NaN]));
        return b.kind === "rigid_link" ? out.slice(0, 2) : outline(out, b.kind);
      }
      const k0 = (i * P + s0) * 2, kn = (i * P + s0 + n - 1) * 2;
      let ex = X[kn] - X[k0], ey = X[kn + 1] - X[k0 + 1];
      const L = Math.hypot(ex, ey) || 1; ex /= L; ey /= L;
      const nx = -ey, ny = ex, out = [];
      for (let q = 0; q < n - 1; q++) {
        const a = (i * P + s0 + q) * 2, c = a + 2;
        const le = Math.hypot(X[c] - X[a], X[c + 1] - X[a + 1]);
        const w1 = D[a] * nx + D[a + 1] * ny, w2 = D[c] * nx + D[c + 1] * ny;
        const u1 = D[a] * ex + D[a + 1] * ey, u2 = D[c] * ex + D[c + 1] * ey;
        const t1 = R[i * P + s0 + q], t2 = R[i * P + s0 + q + 1];
        const f1 = fieldOf(i, s0 + q), f2 = fieldOf(i, s0 + q + 1);
        for (let j = 0; j < SUB; j++) {
          const s = j / SUB, s2 = s * s, s3 = s2 * s;
          const w = (1 - 3 * s2 + 2 * s3) * w1 + (s - 2 * s2 + s3) * le * t1 + (3 * s2 - 2 * s3) * w2 + (s3 - s2) * le * t2;
          const u = (1 - s) * u1 + s * u2;
          out.push([X[a] + s * (X[c] - X[a]) + amp * (u * ex + w * nx), X[a + 1] + s * (X[c + 1] - X[a + 1]) + amp * (u * ey + w * ny),
            (1 - s) * f1 + s * f2]);
        }
      }
      const last = this.pt(i, s0 + n - 1, amp);
      out.push([last[0], last[1], fieldOf(i, s0 + n - 1)]);
      return out;
    }
    ghost(b, i) {
      const out = [];
      for (let p = b.start; p < b.start + b.n; p++) out.push(this.pt(i, p, 0));
      return b.kind === "rigid_link" ? out.slice(0, 2) : b.kind === "body" ? outline(out, "body") : out;
    }
    draw(i, amp, colourOf) {
      const c = this.c; fitCanvas(c);
      if (!this.view) this.fit(amp);
      const g = c.getContext("2d"), T = this.transform(), G = this.g;
      g.setTransform(DPR(), 0, 0, DPR(), 0, 0); g.clearRect(0, 0, c.clientWidth, c.clientHeight);
      g.lineCap = "round"; g.lineJoin = "round";
      for (const j of this.d.joints) {          // the ground under everything
        if (!j.ground) continue;
        const gx = T.sx(j.ground[0]), gy = T.sy(j.ground[1]);
        if (j.axis) {
          const L = 1e4;
          g.strokeStyle = G.ground_guide.colour; g.lineWidth = G.ground_guide.width * PT;
          g.beginPath(); g.moveTo(gx - L * j.axis[0], gy + L * j.axis[1]); g.lineTo(gx + L * j.axis[0], gy - L * j.axis[1]); g.stroke();
        } else glyph(g, G.ground_pivot.marker, gx, gy, G.ground_pivot.size * PT, G.ground_pivot.fill, G.ground_pivot.edge);
      }
      g.strokeStyle = G.ghost.colour; g.lineWidth = G.ghost.width * PT; g.setLineDash(G.ghost.dash.map((v) => v * PT));
      for (const b of this.d.bodies) poly(g, T, this.ghost(b, i));
      g.setLineDash([]);
      this.lines = [];
      this.d.bodies.forEach((b, bi) => {
        const st = G.bodies[b.kind], colour = G.colours[bi % G.colours.length];
        const pts = this.line(b, i, amp, this.field.at);
        this.lines.push([b, pts]);
        if (st.fill && pts.length > 3) {
          g.fillStyle = colour; g.globalAlpha = st.fill; g.beginPath();
          pts.forEach((p, k) => (k ? g.lineTo(T.sx(p[0]), T.sy(p[1])) : g.moveTo(T.sx(p[0]), T.sy(p[1]))));
          g.fill(); g.globalAlpha = 1;
        }
        const wpx = st.width * PT * 1.25;
        if (b.kind === "flexible" && colourOf) {          // wider: the colour must read
          g.strokeStyle = "#444"; g.lineWidth = 2 * wpx + 2; poly(g, T, pts);
          g.lineWidth = 2 * wpx; g.lineCap = "butt";
          for (let k = 0; k + 1 < pts.length; k++) {
            g.strokeStyle = colourOf(0.5 * (pts[k][2] + pts[k + 1][2]));
            g.beginPath(); g.moveTo(T.sx(pts[k][0]), T.sy(pts[k][1])); g.lineTo(T.sx(pts[k + 1][0]), T.sy(pts[k + 1][1])); g.stroke();
          }
          g.lineCap = "round";
        } else { g.strokeStyle = colour; g.lineWidth = wpx; poly(g, T, pts); }
      });
      for (const j of this.d.joints) {
        if (j.point === null) continue;
        const p = this.pt(i, j.point, amp), gl = G.joints[j.kind] || G.joints.revolute;
        glyph(g, gl.marker, T.sx(p[0]), T.sy(p[1]), gl.size * PT, j.driven ? gl.driven_fill : gl.fill, gl.edge);
      }
      state.draws++;
    }
    nearest(px, py) {                            // the drawn station nearest to a canvas point
      const T = this.transform(); let best = null, bd = 14;
      for (const [b, pts] of this.lines) {
        pts.forEach((p, k) => {
          const dd = Math.hypot(T.sx(p[0]) - px, T.sy(p[1]) - py);
          if (dd < bd) { bd = dd; best = { body: b, p, k, n: pts.length }; }
        });
      }
      return best;
    }
    interact() {
      const c = this.c; let drag = null;
      c.addEventListener("wheel", (e) => {
        e.preventDefault();
        const r = c.getBoundingClientRect(), T = this.transform();
        const wx = T.wx(e.clientX - r.left), wy = T.wy(e.clientY - r.top);
        this.zoom *= Math.exp(-e.deltaY * 0.0015);
        const T2 = this.transform();
        this.pan[0] += wx - T2.wx(e.clientX - r.left); this.pan[1] += wy - T2.wy(e.clientY - r.top);
        this.onChange();
      }, { passive: false });
      c.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; c.classList.add("dragging"); });
      window.addEventListener("mouseup", () => { drag = null; c.classList.remove("dragging"); });
      c.addEventListener("mousemove", (e) => {
        if (drag) {
          const k = this.transform().k;
          this.pan[0] -= (e.clientX - drag[0]) / k; this.pan[1] += (e.clientY - drag[1]) / k; drag = [e.clientX, e.clientY];
          this.onChange(); return;
        }
        const r = c.getBoundingClientRect(), hit = this.nearest(e.clientX - r.left, e.clientY - r.top);
        showTip(e, hit ? this.describe(hit) : null);
      });
      c.addEventListener("mouseleave", () => showTip(null));
      c.addEventListener("dblclick", () => { this.zoom = 1; this.pan = [0, 0]; this.onChange(); });
    }
    onChange() {}
    describe() { return ""; }
  }

  function outline(pts, kind) {                  // a rigid body's points around their centroid, closed
    if (kind !== "body" || pts.length < 3) return pts;
    const cx = pts.reduce((s, p) => s + p[0], 0) / pts.length, cy = pts.reduce((s, p) => s + p[1], 0) / pts.length;
    const o = pts.slice().sort((a, b) => Math.atan2(a[1] - cy, a[0] - cx) - Math.atan2(b[1] - cy, b[0] - cx));
    return o.concat([o[0]]);
  }
  function poly(g, T, pts) {
    g.beginPath();
    pts.forEach((p, k) => (k ? g.lineTo(T.sx(p[0]), T.sy(p[1])) : g.moveTo(T.sx(p[0]), T.sy(p[1]))));
    g.stroke();
  }
  function glyph(g, marker, x, y, size, fill, edge) {
    g.fillStyle = fill; g.strokeStyle = edge; g.lineWidth = 1;
    g.beginPath();
    if (marker === "square") g.rect(x - size / 2, y - size / 2, size, size);
    else if (marker === "triangle") { const r = size / 2; g.moveTo(x, y - r); g.lineTo(x + r * 0.87, y + r / 2); g.lineTo(x - r * 0.87, y + r / 2); g.closePath(); }
    else g.arc(x, y, size / 2, 0, 2 * Math.PI);
    g.fill(); g.stroke();
  }

  // ------------------------------------------------------------------ colour bar
  function colourBar(host, range, title, unit) {
    host.innerHTML = "";
    const cv = el("canvas"); host.append(el("div", { class: "cb-title", text: title }), cv);
    const lo = range[0], hi = range[1], m = Math.max(Math.abs(lo), Math.abs(hi)) || 1;
    cv.width = 16; cv.height = 196;
    const g = cv.getContext("2d");
    for (let k = 0; k < cv.height; k++) { g.fillStyle = divColour((hi - (hi - lo) * k / (cv.height - 1)) / m); g.fillRect(0, k, 16, 1); }
    const H = 392, top = 14;
    const label = (v, id) => {
      const lab = el("div", { class: "cb-label", text: fmt(v, 3) + unitText(unit) });
      if (id) { lab.id = id; lab.setAttribute("data-value", String(v)); }
      lab.style.top = (top + (hi - v) / ((hi - lo) || 1) * H) + "px"; host.append(lab);
    };
    label(hi, "cb-max"); label(lo, "cb-min");
    if (lo < 0 && hi > 0 && Math.min(hi, -lo) > 0.12 * (hi - lo)) label(0, null);
    state.colourRange = [lo, hi];
  }

  // ------------------------------------------------------------------ the header
  function header(sub) {
    $("title").textContent = DATA.title || "flexmech result";
    $("subtitle").textContent = sub;
    document.title = (DATA.title || "flexmech") + " — flexmech view";
    const ws = DATA.warnings || [];
    if (!ws.length) return;
    const list = el("ul");
    for (const w of ws) list.append(el("li", {}, el("span", { class: "kind kind-" + w.kind, text: w.kind || "warning" }), w.text));
    const det = el("details", {}, el("summary", { text: ws.length + " warning" + (ws.length > 1 ? "s" : "") + " of this run (the time axes mark where they start)" }), list);
    if (ws.length <= 3) det.open = true;
    $("warnings").append(det);
  }

  function approxSize() { return new Blob([document.documentElement.outerHTML]).size; }
  function sizeText(n) { return n >= 1e6 ? fmt(n / 1e6, 3) + " MB" : fmt(n / 1e3, 3) + " kB"; }

  // ------------------------------------------------------------------ a run
  function runPage() {
    const d = DATA, main = $("main");
    header(`model ${d.model}; ${d.status === "completed" ? "completed" : d.status.toUpperCase() + " (partial results)"}; ` +
      `${d.decimation.frames_kept} frames drawn of ${d.decimation.frames_run}`);
    const mp = el("div", { class: "pane", id: "mech-pane" });
    const canvas = el("canvas", { id: "mech" }), cb = el("div", { class: "colourbar", id: "colourbar" });
    mp.append(el("div", { class: "stage" }, canvas, cb));
    const play = el("button", { id: "play", text: "▶ play" }), slider = el("input", { id: "time", type: "range", min: "0", max: String(d.shapes.frames - 1), step: "1", value: "0" });
    const tRead = el("span", { class: "readout", id: "time-text" });
    mp.append(el("div", { class: "timerow" }, play, slider, tRead));
    const speed = el("select", { id: "speed" });
    [0.1, 0.25, 0.5, 1, 2, 4, 10].forEach((v) => speed.append(el("option", { value: String(v), text: v + "×" })));
    speed.value = "1";
    const mag = el("input", { id: "mag", type: "range", min: "-1", max: "6", step: "0.01", value: String(Math.log10(d.scale)) });
    const magText = el("input", { id: "mag-text", type: "number", min: "0", step: "any", style: "width:6.5em" });
    const magDefault = el("button", { id: "mag-default", text: "default × " + fmt(d.scale, 3) }), magOne = el("button", { id: "mag-one", text: "true scale × 1" });
    const fieldSel = el("select", { id: "field" });
    if (d.field) { fieldSel.append(el("option", { value: "strain", text: "bending strain" }), el("option", { value: "stress", text: "bending stress" })); }
    fieldSel.append(el("option", { value: "none", text: "link colours" }));
    const speedText = el("span", { class: "readout", id: "speed-text" });
    const save = el("button", { id: "save-png", text: "save PNG" });
    mp.append(el("div", { class: "controls" }, el("label", { text: "speed " }), speed, speedText),
      el("div", { class: "controls" }, el("label", { text: "deflection magnification ×" }), magText, mag, magDefault, magOne),
      el("div", { class: "controls" }, el("label", { text: "colour " }), fieldSel, save));
    const marks = d.marks;
    const legend = el("div", { class: "legend-row", id: "glyph-legend" });
    mp.append(legend, el("div", { class: "note", id: "field-note" }));
    const cp = el("div", { class: "pane", id: "curve-pane" });
    main.append(mp, cp);

    const M = new Mechanism(canvas, d, { at: () => NaN });
    const key = M.key, t0 = key[0], t1 = Math.max(d.t_end || key[key.length - 1], key[key.length - 1]);
    const bodies = d.bodies;
    const bodyOf = new Int32Array(M.P);
    bodies.forEach((b, bi) => { for (let p = b.start; p < b.start + b.n; p++) bodyOf[p] = bi; });
    let field = d.field ? "strain" : "none", scale = d.scale, frame = 0, playing = false, rate = 1;
    const span = t1 - t0 || 1, baseRate = span / 12;   // the whole run in 12 s at 1x
    const fieldAt = (i, p) => {
      if (field === "none" || !M.kappa) return NaN;
      const b = bodies[bodyOf[p]], k = M.kappa[i * M.P + p];
      if (b.half_depth === null) return NaN;
      return field === "strain" ? b.half_depth * k : b.E * b.half_depth * k / 1e6;
    };
    M.field.at = fieldAt;
    const colourOf = () => {
      if (field === "none") return null;
      const r = d.field[field], m = Math.max(Math.abs(r.min), Math.abs(r.max)) || 1;
      return (v) => divColour(v / m);
    };
    function legendText() {
      const words = [];
      const J = d.glyphs.joints;
      words.push(J.revolute.legend);
      if (d.joints.some((j) => j.driven)) words.push("● driven joint");
      if (d.joints.some((j) => j.ground && !j.axis)) words.push(d.glyphs.ground_pivot.legend);
      if (d.joints.some((j) => j.kind === "prismatic")) words.push(J.prismatic.legend + (d.joints.some((j) => j.axis) ? " " + d.glyphs.ground_guide.legend : ""));
      legend.textContent = "rigid configuration dashed (the ghost); " + words.join(", ") + "; wheel: zoom, drag: pan, double click: fit";
    }
    legendText();
    function setField() {
      if (field === "none") {
        cb.style.visibility = "hidden"; state.colourRange = null;
        $("field-note").textContent = d.field ? "" : "No strain along the links: this shape.csv has no curvatures (written before flexmech wrote them); run the case again with --view.";
      } else {
        cb.style.visibility = "visible";
        const r = d.field[field];
        colourBar(cb, [r.min, r.max], field === "strain" ? "strain [-]" : "stress [MPa]", r.unit);
        $("field-note").textContent = r.label + " (c the link's half depth, κ its curvature), over every frame and station drawn; " +
          "blue compression, red tension of the fibre at η = −c.";
      }
      state.field = field; redraw();
    }
    function setScale(s, refit) {
      scale = s; state.scale = s;
      mag.value = String(Math.log10(s)); magText.value = fmt(s, 4);
      if (refit) M.fit(s);
      redraw();
    }
    function redraw() {
      M.draw(frame, scale, colourOf());
      const t = key[frame];
      tRead.textContent = "t = " + fmt(t, 5) + " s (frame " + (frame + 1) + "/" + M.F + ")";
      state.frame = frame; state.time = t;
      charts.forEach((c) => c.setCursor(t));
      heads.forEach((h) => h());
      state.cursors = charts.map((c) => c.cursor);
    }
    M.describe = (hit) => {
      const b = hit.body;
      const lines = [`<b>${esc(b.name)}</b> (${b.kind.replace("_", " ")})`];
      if (b.kind === "flexible") {
        const s = hit.k / Math.max(hit.n - 1, 1);
        lines.push("at " + fmt(100 * s, 3) + " % of its length");
        const kap = hit.p[2];
        if (field !== "none" && isFinite(kap)) lines.push(d.field[field].label.split(" at")[0] + ": " + fmt(kap, 4) + unitText(d.field[field].unit));
      }
      lines.push("t = " + fmt(key[frame], 5) + " s");
      return lines.join("<br>");
    };
    M.onChange = redraw;
    function setFrame(i) { frame = Math.max(0, Math.min(M.F - 1, Math.round(i))); slider.value = String(frame); redraw(); }
    function frameAt(t) { return search(key, t); }
    slider.addEventListener("input", () => { frame = +slider.value; redraw(); });
    let last = null, simT = 0;
    function tick(now) {
      if (!playing) return;
      if (last !== null) {
        simT += (now - last) / 1000 * baseRate * rate;
        if (simT > key[M.F - 1]) simT = key[0];
        frame = frameAt(simT); slider.value = String(frame); redraw();
      }
      last = now; requestAnimationFrame(tick);
    }
    function setPlaying(on) {
      playing = on; play.textContent = on ? "❚❚ pause" : "▶ play"; play.classList.toggle("on", on); state.playing = on;
      if (on) { simT = key[frame]; last = null; requestAnimationFrame(tick); }
    }
    play.addEventListener("click", () => setPlaying(!playing));
    const speedLabel = () => { speedText.textContent = "= " + fmt(baseRate * rate, 3) + "× real time (the run in " + fmt(12 / rate, 3) + " s)"; };
    speed.addEventListener("change", () => { rate = +speed.value; speedLabel(); });
    speedLabel();
    mag.addEventListener("input", () => setScale(Math.pow(10, +mag.value), true));
    magText.addEventListener("change", () => { const v = +magText.value; if (v > 0) setScale(v, true); });
    magDefault.addEventListener("click", () => setScale(d.scale, true));
    magOne.addEventListener("click", () => setScale(1, true));
    fieldSel.addEventListener("change", () => { field = fieldSel.value; setField(); });
    save.addEventListener("click", () => {
      const a = el("a", { download: "flexmech-frame-" + (frame + 1) + ".png", href: canvas.toDataURL("image/png") });
      document.body.append(a); a.click(); a.remove();
    });
    window.addEventListener("resize", () => { charts.forEach((c) => c.draw()); redraw(); });

    // the curves
    const charts = [], heads = [];
    const spans = [];
    if (marks.valid_until !== null) spans.push({ lo: marks.valid_until, hi: t1, colour: "#c0392b", alpha: 0.10, label: "outside the model's validity →", text: "#a93226" });
    if (marks.failed_at !== null) spans.push({ lo: marks.failed_at, hi: t1, colour: "#000", alpha: 0.14, label: "the run stopped here", text: "#333", row: 1 });
    const evMarks = marks.events.map((e) => ({ x: e.t, colour: e.kind === "validity" ? "#c0392b" : "#d68910", text: e.text }));
    cp.append(el("div", { class: "note", text: "Outputs against time: the black line follows the time slider, a click moves it there; hover for values. " +
      (marks.valid_until !== null ? "Shaded red: after t = " + fmt(marks.valid_until, 4) + " s the results are outside the model's validity. " : "") +
      (evMarks.length ? "▼ marks where a limit is passed (hover it). " : "") }));
    d.curves.forEach((panel, pi) => {
      const series = panel.series.map((s, k) => ({ name: s.name, colour: PALETTE[k % PALETTE.length], x: decode(s.t, Float32Array), y: decode(s.y, Float32Array), error: s.error }));
      const head = el("div", { class: "phead" });
      const vals = series.map((s) => {
        const v = el("span", { class: "val" });
        const e = errorText(s.error);
        head.append(el("span", {}, el("span", { class: "sw", style: "background:" + s.colour }), s.name + " ", v, e));
        return v;
      });
      const cv = el("canvas", { class: "curve", "data-panel": String(pi) });
      const box = el("div", { class: "panel" }, head, cv);
      cp.append(box);
      const ch = new Chart(cv, {
        xmin: t0, xmax: t1, xlabel: "t [s]", ylabel: "[" + panel.unit + "]", series, spans: spans.map((s) => (pi ? Object.assign({}, s, { label: "" }) : s)),
        marks: evMarks.concat(series.filter((s) => s.error && s.error.t_time !== undefined && s.error.time > 1e-4).map((s) => ({ x: s.error.t_time, colour: s.colour, text: s.name + ": largest time-step error (step doubling) here" }))),
        onPick: (x) => { setPlaying(false); setFrame(frameAt(x)); },
        readout: (x, near) => {
          const rows = ["t = " + fmt(x, 5) + " s"];
          series.forEach((s) => { const i = search(s.x, x); rows.push(`<span style="color:${s.colour}">■</span> ${esc(s.name)}: ${fmt(s.y[i], 5)}${unitText(panel.unit)} <span style="color:#888">(t = ${fmt(s.x[i], 5)})</span>`); });
          near.forEach((m) => rows.push("▼ " + esc(m.text)));
          return rows.join("<br>");
        },
      });
      charts.push(ch);
      heads.push(() => series.forEach((s, k) => { const i = search(s.x, key[frame]); vals[k].textContent = "= " + fmt(s.y[i], 4) + unitText(panel.unit); }));
    });
    const dec = d.decimation, kept = dec.frames_kept;
    $("footer").append(el("div", { id: "decimation", text:
      `This page holds ${kept} of the run's ${dec.frames_run} frames (shape.csv kept ${dec.frames_stored}; spread evenly, ` +
      `${fmt((t1 - t0) / Math.max(kept - 1, 1), 3)} s apart) and ${dec.points_kept} drawn points` +
      (dec.points_dropped ? ` (${dec.points_dropped} mesh nodes left out)` : "") + `; the bound: ${dec.rule}. ` +
      `Curves: hover values are those of the drawn samples. File size about ${sizeText(approxSize())}. ` +
      "Made by flexmech view; it needs no network and no server." }));
    charts.forEach((c) => c.draw());
    setScale(d.scale, true);
    setField();
    Object.assign(state, { setFrame, setScale, frames: M.F, play: () => setPlaying(true), pause: () => setPlaying(false),
      setField: (f) => { fieldSel.value = f; field = f; setField(); }, defaultScale: d.scale });
  }

  function errorText(e) {
    if (!e || (e.time === undefined && e.total === undefined) || (e.total === undefined && !(e.time > 0))) return "";
    const span = el("span", { class: "err" });
    if (e.total !== undefined) {
      const parts = ["time", "mesh", "model"].filter((k) => e[k] !== undefined).map((k) => k + " " + pct(e[k]));
      span.textContent = "± " + pct(e.total) + " of its peak (" + parts.join(", ") + ")" + (e.negligible ? "; negligible" : "");
      if (e.tolerance !== undefined && e.total > e.tolerance && !e.negligible) { span.classList.add("over"); span.textContent += " > tolerance " + pct(e.tolerance); }
    } else span.textContent = "time-step error " + pct(e.time) + " of its peak";
    return span;
  }

  // ------------------------------------------------------------------ modes
  function modesPage() {
    const d = DATA, main = $("main");
    header(d.modes ? `mode shapes, model ${d.model}, ${d.where}` + (d.geometric !== "none" ? ", geometric stiffness" : "")
      : `frozen natural frequencies along the motion, model ${d.model}`);
    if (d.modes) modeShapes(d, main);
    if (d.along) alongChart(d.along, main);
  }

  function modeShapes(d, main) {
    const mp = el("div", { class: "pane", id: "mech-pane" });
    const canvas = el("canvas", { id: "mech" }), cb = el("div", { class: "colourbar", id: "colourbar" });
    const list = el("div", { class: "modes-list", id: "modes-list" });
    const play = el("button", { id: "play", text: "❚❚ pause" }), amp = el("input", { id: "amp", type: "range", min: "0", max: "3", step: "0.05", value: "1" });
    const ampText = el("span", { class: "readout", id: "amp-text" }), info = el("div", { class: "note", id: "mode-info" });
    mp.append(el("div", { class: "stage" }, canvas, cb), list, el("div", { class: "controls" }, play, el("label", { text: "amplitude" }), amp, ampText), info);
    main.append(mp);
    const M = new Mechanism(canvas, d, { at: () => NaN });
    let mode = 0, playing = true, phase = Math.PI / 2, last = null, ampF = 1;
    M.field.at = (i, p) => (M.kappa ? M.kappa[i * M.P + p] * Math.sin(phase) : NaN);
    colourBar(cb, [-1, 1], "relative strain", "");
    const buttons = d.modes.map((m, k) => {
      const b = el("button", { "data-mode": String(k + 1), text: `mode ${m.mode}: ` + (m.kind === "rigid" ? "rigid (a free DOF)" : fmt(m.f_hz, 4) + " Hz") });
      b.addEventListener("click", () => { mode = k; buttons.forEach((x, j) => x.classList.toggle("on", j === k)); describe(); redraw(); });
      list.append(b); return b;
    });
    buttons[0].classList.add("on");
    function describe() {
      const m = d.modes[mode];
      info.textContent = `mode ${m.mode}: ${m.kind === "rigid" ? "a rigid-body mode (a free degree of freedom of the mechanism), 0 Hz" : fmt(m.f_hz, 5) + " Hz, elastic"}. ` +
        `Drawn with its largest displacement ${fmt(100 * d.fraction * ampF, 3)} % of the mechanism's size at the extremes (a mode's amplitude is arbitrary), ` +
        "oscillating slowly (one cycle in 1.6 s); colour: its bending strain relative to its largest, in phase with the motion.";
    }
    function redraw() {
      M.draw(mode, ampF * Math.sin(phase), (v) => divColour(v));
      Object.assign(state, { mode: mode + 1, phase });
    }
    M.onChange = redraw;
    M.fit(1.0);
    function tick(now) {
      if (!playing) { last = null; return; }
      if (last !== null) phase = (phase + (now - last) / 1000 * 2 * Math.PI / 1.6) % (2 * Math.PI);
      last = now; redraw(); requestAnimationFrame(tick);
    }
    play.addEventListener("click", () => { playing = !playing; play.textContent = playing ? "❚❚ pause" : "▶ play"; state.playing = playing; if (playing) requestAnimationFrame(tick); });
    amp.addEventListener("input", () => { ampF = +amp.value; ampText.textContent = "× " + fmt(ampF, 3); M.fit(Math.max(ampF, 1e-3)); describe(); redraw(); });
    ampText.textContent = "× 1";
    M.describe = (hit) => `<b>${esc(hit.body.name)}</b> (${hit.body.kind.replace("_", " ")})` +
      (isFinite(hit.p[2]) ? "<br>relative strain " + fmt(hit.p[2], 3) : "");
    window.addEventListener("resize", redraw);
    describe(); redraw(); state.playing = true; requestAnimationFrame(tick);
    Object.assign(state, { setMode: (k) => buttons[k - 1].click(), setPhase: (p) => { phase = p; redraw(); },
      pause: () => { if (playing) play.click(); }, play: () => { if (!playing) play.click(); }, modes: d.modes.length });
    $("footer").append(el("div", { text: "Made by flexmech view from modes.json and mode_shapes.csv; it needs no network and no server." }));
  }

  function alongChart(a, main) {
    const pane = el("div", { class: "pane", id: "along-pane" }), cv = el("canvas", { id: "along", style: "height:420px" });
    pane.append(el("div", { class: "note", text: `Frozen natural frequencies at ${a.x.length} positions over ${a.span}; grey: the crank speed harmonics kΩ/2π, × where a frequency meets one. Hover for values.` }), cv);
    main.append(pane);
    const series = a.series.map((s, k) => ({ name: s.name, colour: PALETTE[k % PALETTE.length], x: s.x, y: s.y, markers: true, radius: 2 }));
    a.harmonics.forEach((h) => series.push({ name: h.k + "Ω", tag: h.k <= 5 || h.k % 5 === 0 ? h.k + "Ω" : "", colour: "#aaa", x: a.x, y: h.y, width: 0.8, dash: h.k % 5 === 0 || h.k === 1 ? [] : [2, 3], noRange: true, noCursor: true }));
    if (a.crossings.length) series.push({ name: "crossings", kind: "points", colour: "#000", x: a.crossings.map((c) => c.x), y: a.crossings.map((c) => c.f_hz), radius: 3, noRange: true });
    const top = 1.12 * Math.max(...a.series.flatMap((s) => s.y.filter(isFinite)));
    const ch = new Chart(cv, {
      xmin: Math.min(...a.x), xmax: Math.max(...a.x), ymin: 0, ymax: top, xlabel: a.xlabel, ylabel: "natural frequency [Hz]", series,
      readout: (x) => {
        const rows = [esc(a.xlabel.split(" [")[0]) + " = " + fmt(x, 4) + (a.xlabel.includes("deg") ? "°" : " s")];
        series.filter((s) => s.name.startsWith("f")).forEach((s) => { const i = search(s.x, x); rows.push(`<span style="color:${s.colour}">■</span> ${s.name} = ${fmt(s.y[i], 4)} Hz`); });
        const near = a.crossings.filter((c) => Math.abs(ch.X(c.x) - ch.X(x)) < 5);
        near.forEach((c) => rows.push(`× f${c.mode} = ${c.harmonic}Ω/2π = ${fmt(c.f_hz, 4)} Hz`));
        return rows.join("<br>");
      },
    });
    ch.draw();
    window.addEventListener("resize", () => ch.draw());
    state.along = ch;
  }

  // ------------------------------------------------------------------ stability chart
  function stabilityPage() {
    const d = DATA, main = $("main");
    header("Floquet stability chart; " + d.settings);
    const pane = el("div", { class: "pane", id: "chart-pane" });
    const top = el("canvas", { id: "growth", style: "height:330px" }), bottom = el("canvas", { id: "bands", style: "height:380px" });
    pane.append(el("div", { class: "note", text: `Growth rate ln max|μ| / T against crank speed (symmetric log scale), unstable above ${d.threshold} 1/s; shaded: the unstable regions, labelled by their multiplier (+1, −1, complex pair ±angle). Below: the frozen natural-frequency bands along the cycle and the lines kΩ/2. Hover for values.` }), top, bottom);
    main.append(pane);
    const sp = d.speed, xmin = Math.min(...sp), xmax = Math.max(...sp);
    const y = d.points.map((p) => p.y);
    const spans = d.regions.map((r, k) => ({ lo: r.lo, hi: r.hi, colour: MU_COLOURS[r.type] || "#999", alpha: 0.14, label: r.hi - r.lo > 0.015 * (xmax - xmin) ? r.label : "", align: "center", row: k % 3 }));
    const ymax = Math.max(10, ...y) * 30, ymin = Math.min(-1e-3, 3 * Math.min(...y));
    const g1 = new Chart(top, {
      xmin, xmax, ymin, ymax, scale: "symlog", linthresh: 1e-3, xlabel: "crank speed Ω [rad/s]", ylabel: "growth rate [1/s]", spans,
      hbands: [{ lo: ymin, hi: d.threshold, colour: "#2ca02c", alpha: 0.10 }], hlines: [{ y: d.threshold, colour: "#2ca02c" }],
      series: [{ name: "growth rate", colour: "#333", x: sp, y, width: 0.7, noCursor: true },
        { name: "samples", kind: "points", colour: "#000", x: sp, y, colours: d.points.map((p) => MU_COLOURS[p.type] || "#555"), radius: 3 }],
      readout: (x) => {
        const i = search(sp, x), p = d.points[i];
        const reg = d.regions.filter((r) => x >= r.lo && x <= r.hi);
        return `Ω = ${fmt(p.x, 5)} rad/s<br>growth rate ${fmt(p.y, 4)} 1/s, max|μ| = ${fmt(p.mu, 6)}<br>` +
          (p.type === "stable" ? "stable" : "unstable: " + ({ "real+": "real multiplier +1 side", "real-": "real −1 side (period doubling)", complex: "complex pair" }[p.type] || p.type)) +
          reg.map((r) => `<br>region ${fmt(r.from, 5)}–${fmt(r.to, 5)} rad/s, ${esc(r.label)}, max|μ| ${fmt(r.max_abs_mu, 4)} at ${fmt(r.at, 5)}`).join("");
      },
    });
    const series = d.bands.map((b, k) => ({ name: b.name, kind: "band", colour: PALETTE[k], x: sp, lo: b.lo, hi: b.hi }));
    const topF = 1.15 * Math.max(...d.bands[d.bands.length - 1].hi);
    d.harmonics.forEach((k) => series.push({ name: k % 2 ? k + "Ω/2" : (k === 2 ? "Ω" : k / 2 + "Ω"), tag: k % 2 ? k + "Ω/2" : (k === 2 ? "Ω" : k / 2 + "Ω"), colour: "#999", x: [xmin, xmax], y: [k * xmin / 2, k * xmax / 2], width: 0.8, dash: k % 2 ? [2, 3] : [], noRange: true, noCursor: true }));
    const g2 = new Chart(bottom, {
      xmin, xmax, ymin: 0, ymax: topF, xlabel: "crank speed Ω [rad/s]", ylabel: "frequency [rad/s]", series, spans: spans.map((s) => Object.assign({}, s, { label: "" })),
      readout: (x) => {
        const i = search(sp, x);
        return `Ω = ${fmt(sp[i], 5)} rad/s` + d.bands.map((b, k) => `<br><span style="color:${PALETTE[k]}">■</span> ${b.name}: ${fmt(b.lo[i], 4)} … ${fmt(b.hi[i], 4)} rad/s`).join("") +
          "<br>kΩ/2 for k = 1..: " + d.harmonics.slice(0, 4).map((k) => fmt(k * x / 2, 4)).join(", ") + " … rad/s";
      },
    });
    g1.draw(); g2.draw();
    window.addEventListener("resize", () => { g1.draw(); g2.draw(); });
    if (d.failed.length) $("footer").append(el("div", { text: d.failed.length + " speed(s) failed: " + d.failed.map((f) => fmt(f.x, 5) + " rad/s (" + f.error + ")").join("; ") }));
    $("footer").append(el("div", { text: "Made by flexmech view from stability.csv and stability_regions.csv; it needs no network and no server." }));
    state.charts = [g1, g2];
  }

  ({ run: runPage, modes: modesPage, stability: stabilityPage })[DATA.kind]();
  state.ready = true;
})();
