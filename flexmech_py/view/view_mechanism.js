/* flexmech view, part 2 of 3: the mechanism on a canvas, the colour bar, the page's header. */
// ------------------------------------------------------------------ mechanism
/* The mechanism on a canvas: the rigid configuration dashed (the ghost), the deformed bodies (a
   flexible link's nodes joined by the cubic Hermite interpolation of its displacement and slope,
   coloured by a field along its length), the joints and the ground with the glyphs of
   flexmech_py.figures.glyphs; wheel zooms, dragging pans, a double click fits the view again. */
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
    g.strokeStyle = "#333"; g.lineWidth = PT;     // a kind's own outline (pitch circles, a slot): Joint.glyph_shapes
    for (const j of this.d.joints) {
      if (j.point === null || !j.shapes || !j.shapes.length) continue;
      const ends = j.ends.map((e) => (e === null ? null : Array.isArray(e) ? e : this.pt(i, e, amp)));
      if (ends[0] && ends[1]) for (const line of shapeLines(j.shapes, ends[0], ends[1])) poly(g, T, line);
    }
    for (const j of this.d.joints) {
      if (j.point === null) continue;
      const p = this.pt(i, j.point, amp), gl = G.joints[j.kind] || G.joints.revolute;   // every kind is in the table (flexmech_py.figures.glyphs)
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

function ring(c, r, n) {                       // a circle of radius r about c, n points, closed
  const out = [];
  for (let k = 0; k < n; k++) { const t = (2 * Math.PI * k) / (n - 1); out.push([c[0] + r * Math.cos(t), c[1] + r * Math.sin(t)]); }
  return out;
}
function shapeLines(shapes, pa, pb) {           // the polylines of a joint kind's outline: flexmech_py.figures.glyphs.shape_lines
  const out = [];
  for (const sh of shapes) {
    if (sh.shape === "circle") out.push(ring(sh.at ? pb : pa, sh.radius, 73));
    else if (sh.shape === "segment") out.push([pa, pb]);
    else if (sh.shape === "slot") {
      const dx = pb[0] - pa[0], dy = pb[1] - pa[1], dist = Math.hypot(dx, dy);
      const u = dist > 1e-9 ? [dx / dist, dy / dist] : sh.axis, n = [-u[1], u[0]];
      const half = sh.half === null ? 1.15 * dist : sh.half, w = 0.05 * Math.max(half, 1e-3), line = [];
      for (const side of [1, -1]) for (let k = 0; k < 13; k++) {
        const t = -0.5 * Math.PI + (Math.PI * k) / 12, cx = Math.cos(t) * u[0] + Math.sin(t) * n[0], cy = Math.cos(t) * u[1] + Math.sin(t) * n[1];
        line.push([pa[0] + side * (half * u[0] + w * cx), pa[1] + side * (half * u[1] + w * cy)]);
      }
      line.push(line[0]);
      out.push(line, ring(pb, 0.8 * w, 25));
    }
  }
  return out;
}
state.shapeLines = shapeLines;                  // reachable from outside the page's scope (tests/test_view_browser.py)
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
