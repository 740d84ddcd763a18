/* flexmech view, part 3 of 3: the page of a run, of a modes result, of a stability chart. */
// ------------------------------------------------------------------ a run
function runPage() {
  const d = DATA, main = $("main");
  header(`model ${d.model}; ${d.status === "completed" ? "completed" : d.status.toUpperCase() + " (partial results)"}; ` +
    `${d.decimation.frames_kept} frames drawn of ${d.decimation.frames_run}`);
  const { mp, canvas, cb, play, slider, tRead, speed, mag, magText, magDefault, magOne, fieldSel, speedText, save } = runControls(d);
  let charts = [], heads = [];
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
    // the joints' words: flexmech_py.figures.glyphs.legend_words, the same as the PNG drawings' legend
    legend.textContent = "rigid configuration dashed (the ghost); " + d.legend.join(", ") + "; wheel: zoom, drag: pan, double click: fit";
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
    heads.forEach((h) => h(t));
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

  ({ charts, heads } = runCurves(d, cp, t0, t1, (x) => { setPlaying(false); setFrame(frameAt(x)); }));
  $("footer").append(decimationNote(d, t0, t1));
  charts.forEach((c) => c.draw());
  setScale(d.scale, true);
  setField();
  Object.assign(state, { setFrame, setScale, frames: M.F, play: () => setPlaying(true), pause: () => setPlaying(false),
    setField: (f) => { fieldSel.value = f; field = f; setField(); }, defaultScale: d.scale });
}

// the mechanism's pane of a run: canvas, colour bar, time slider and the controls (elements only)
function runControls(d) {
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
  return { mp, canvas, cb, play, slider, tRead, speed, mag, magText, magDefault, magOne, fieldSel, speedText, save };
}

// the output curves of a run, one chart per panel, the validity and error marks on their time axes;
// heads: one function per panel that writes its curves' values at time t into its heading
function runCurves(d, cp, t0, t1, onPick) {
  const marks = d.marks;
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
      onPick,
      readout: (x, near) => {
        const rows = ["t = " + fmt(x, 5) + " s"];
        series.forEach((s) => { const i = search(s.x, x); rows.push(`<span style="color:${s.colour}">■</span> ${esc(s.name)}: ${fmt(s.y[i], 5)}${unitText(panel.unit)} <span style="color:#888">(t = ${fmt(s.x[i], 5)})</span>`); });
        near.forEach((m) => rows.push("▼ " + esc(m.text)));
        return rows.join("<br>");
      },
    });
    charts.push(ch);
    heads.push((t) => series.forEach((s, k) => { const i = search(s.x, t); vals[k].textContent = "= " + fmt(s.y[i], 4) + unitText(panel.unit); }));
  });
  return { charts, heads };
}

// what the page holds of the run, the rule that bounds it and what that costs, measured
function decimationNote(d, t0, t1) {
  const dec = d.decimation, kept = dec.frames_kept;
  const miss = dec.points_dropped ? `; the line drawn through the nodes kept passes within ${pct(dec.deflection_error)} of the ` +
    `largest displacement of every node left out, and the colour there within ${pct(dec.curvature_error)} of the link's largest curvature` : "";
  return el("div", { id: "decimation", text:
    `This page holds ${kept} of the run's ${dec.frames_run} frames (shape.csv kept ${dec.frames_stored}; spread evenly, ` +
    `${fmt((t1 - t0) / Math.max(kept - 1, 1), 3)} s apart: vibrations faster than ${fmt(Math.max(kept - 1, 1) / (2 * (t1 - t0)), 3)} Hz ` +
    `are not resolved by the animation, the curves hold them) and ${dec.points_kept} drawn points` +
    (dec.points_dropped ? ` (${dec.points_dropped} mesh nodes left out)` : "") + miss + `. The bound: ${dec.rule}. ` +
    (dec.curve_bucket_s > 0 ? `Curves: the smallest and largest sample of every ${fmt(dec.curve_bucket_s, 3)} s drawn (every peak and trough); ` +
      `read as a line between the drawn points a curve misses a sample of timeseries.csv by up to ${pct(dec.curve_error)} of its peak ` +
      "(vibrations faster than two of those spans show as a band); hover values are those of the drawn samples."
      : "Curves: every sample of timeseries.csv drawn.") + ` File size about ${sizeText(approxSize())}. Made by flexmech view; it needs no network and no server.` });
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
  d.harmonics.forEach((k) => series.push({ name: k === 1 ? "Ω/2" : k % 2 ? k + "Ω/2" : (k === 2 ? "Ω" : k / 2 + "Ω"), tag: k === 1 ? "Ω/2" : k % 2 ? k + "Ω/2" : (k === 2 ? "Ω" : k / 2 + "Ω"), colour: "#999", x: [xmin, xmax], y: [k * xmin / 2, k * xmax / 2], width: 0.8, dash: k % 2 ? [2, 3] : [], noRange: true, noCursor: true }));
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
