// Simulator evidence on the video's playhead: one canvas of tracks sharing a time axis
// (phases, gripper opening, grasp, contacts, displacement per object, goal progress), with
// the playhead and the failure times marked. Above it, two label lanes in the DOM: the time
// markers' labels and the simulator events' labels (with a tooltip; events close in time are
// stacked, so none hides another). Click or drag anywhere on the tracks to seek.
import { EVENT, FILLS, MARKERS, OBJECT_PALETTE, PHASE_COLORS, PLAYHEAD, dashCss } from "./colors.js";
import { h } from "./dom.js";

const GUTTER = 104;
const RIGHT = 10;
const LANE = 15;         // height of one label line in the lanes
const MAX_STACK = 3;     // event labels shown per stack; the rest is "+n" (all in the tooltip)
const ROWS = [
  { key: "phases", label: "phases", h: 16 },
  { key: "gripper", label: "gripper opening", h: 30 },
  { key: "grasp", label: "grasp", h: 12 },
  { key: "contacts", label: "contacts", h: 12 },
  { key: "disp", label: "displacement", h: 58 },
  { key: "goal", label: "goal progress", h: 20 },
];
const GAP = 4;

// "object_toppled" + "akita_black_bowl_1" -> "toppled · black bowl"
function shortEvent(e) {
  const kind = e.kind.replace(/^object_/, "").replaceAll("_", " ");
  const obj = e.object ? e.object.replace(/_\d+$/, "").split("_").slice(-2).join(" ") : "";
  return obj ? `${kind} · ${obj}` : kind;
}
const longEvent = (e) => `${e.time_s.toFixed(2)} s · ${e.kind.replaceAll("_", " ")}${e.object ? ` · ${e.object}` : ""}${e.detail ? ` · ${e.detail}` : ""}`;

export class Tracks {
  constructor({ evidence, media, markers = [], onSeek }) {
    this.ev = evidence;
    this.hz = media.control_hz || 20;
    this.phases = media.phases;
    this.events = [...(media.events || [])].sort((a, b) => a.time_s - b.time_s);
    this.markers = markers;
    this.onSeek = onSeek;
    this.t = 0;
    const times = evidence ? evidence.time_s : [];
    this.duration = Math.max(media.duration_s || 0, times.length ? times[times.length - 1] : 0, 0.1);
    this.objects = evidence ? Object.keys(evidence.displacement) : [];
    this.colors = Object.fromEntries(this.objects.map((o, i) => [o, OBJECT_PALETTE[i % OBJECT_PALETTE.length]]));
    this.maxDisp = Math.max(0.02, ...this.objects.flatMap((o) => evidence.displacement[o].filter((x) => x != null)));
    this.maxGrip = Math.max(0.01, ...(evidence ? evidence.gripper_opening : [0]));
    this.canvas = h("canvas", { className: "tracks-canvas", id: "tracks" });
    this.markerLane = h("div", { className: "lane marker-lane", id: "marker-lane" }, h("span", { className: "lane-label" }, "times"));
    this.eventLane = h("div", { className: "lane event-lane", id: "event-lane" }, h("span", { className: "lane-label" }, "events"));
    this.tip = h("div", { className: "ev-tip", id: "ev-tip", role: "tooltip", hidden: true });
    this.area = h("div", { className: "track-area" }, this.markerLane, this.eventLane, this.canvas, this.tip);
    this.readout = h("div", { className: "ev-readout", id: "ev-readout" });
    const targets = new Set(evidence ? evidence.targets || [] : []);
    this.legendEl = h("div", { className: "legend", id: "legend" },
      ...this.objects.map((o) => h("span", { className: `obj-key${targets.has(o) ? " target" : ""}`, dataset: { object: o } },
        h("i", { style: `background:${this.colors[o]}` }), o, targets.has(o) ? " (target)" : "")),
      ...this.markerLegend());
    this.el = h("div", { className: "tracks" },
      evidence ? this.area : h("p", { className: "muted" }, "No simulator evidence for this episode."),
      this.legendEl, this.readout);
    this._wire();
  }

  style(m) { return { ...(MARKERS[m.kind] || {}), ...(m.style || {}) }; }
  markerLegend() {
    // a model marker without a time (quarantined output) has nothing to explain
    return this.markers.filter((m) => m.t != null || m.kind !== "model").map((m) => h("span", { className: "marker-key" },
      h("i", { className: "line", style: `background:${dashCss(this.style(m))}` }), m.label));
  }
  setMarkers(markers) {
    this.markers = markers;
    this.legendEl.querySelectorAll(".marker-key").forEach((n) => n.remove());
    this.legendEl.append(...this.markerLegend());
    this.draw();
  }
  setPlayhead(t) { this.t = t; this.draw(); this.updateReadout(); }

  x(t, w) { return GUTTER + (w - GUTTER - RIGHT) * Math.min(1, Math.max(0, t / this.duration)); }
  tAt(px, w) { return Math.min(this.duration, Math.max(0, (px - GUTTER) / (w - GUTTER - RIGHT) * this.duration)); }
  index(t) {
    const ts = this.ev.time_s;
    let lo = 0, hi = ts.length - 1;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (ts[mid] < t) lo = mid + 1; else hi = mid; }
    return lo > 0 && Math.abs(ts[lo - 1] - t) < Math.abs(ts[lo] - t) ? lo - 1 : lo;
  }

  _wire() {
    if (!this.ev) return;
    const seek = (e) => {
      const r = this.area.getBoundingClientRect();
      if (e.clientX - r.left < GUTTER) return;
      this.onSeek(this.tAt(e.clientX - r.left, r.width));
    };
    let dragging = false;
    this.area.addEventListener("pointerdown", (e) => {
      if (e.target.closest(".ev-stack")) return;  // an event label seeks to its event (below)
      dragging = true; this.area.setPointerCapture(e.pointerId); seek(e);
    });
    this.area.addEventListener("pointermove", (e) => { if (dragging) seek(e); });
    this.area.addEventListener("pointerup", () => { dragging = false; });
    new ResizeObserver(() => this.draw()).observe(this.area);
  }

  // labels of a lane placed left to right; a label that would overlap the one before goes on
  // the next line, so labels at one time stack instead of hiding each other
  _place(items, w, widthOf) {
    const ends = [];
    return items.map((it) => {
      const x = this.x(it.t, w), width = widthOf(it);
      let line = ends.findIndex((end) => x >= end + 4);
      if (line < 0) { line = ends.length; ends.push(0); }
      ends[line] = x + width;
      return { ...it, x, line };
    });
  }

  _drawMarkerLane(w) {
    const shown = this.markers.filter((m) => m.t != null).map((m) => ({ t: m.t, m }));
    const placed = this._place(shown, w, (it) => 8 + 6.5 * `${it.m.short || it.m.label} ${it.t.toFixed(2)}`.length);
    const lines = Math.max(1, ...placed.map((p) => p.line + 1));
    this.markerLane.style.height = `${lines * LANE + 2}px`;
    this.markerLane.querySelectorAll(".mtag").forEach((n) => n.remove());
    for (const p of placed) {
      const s = this.style(p.m);
      this.markerLane.append(h("span", {
        className: "mtag", dataset: { kind: p.m.kind || "", t: String(p.t) }, title: `${p.m.label}: ${p.t.toFixed(2)} s`,
        style: `left:${p.x}px; top:${p.line * LANE}px; border-left: 3px solid ${s.color}; color:${s.color}`,
      }, `${p.m.short || p.m.label} ${p.t.toFixed(2)}`));
    }
  }

  _drawEventLane(w) {
    // events within one label's width of each other form one stack
    const stacks = [];
    for (const e of this.events) {
      const x = this.x(e.time_s, w), last = stacks[stacks.length - 1];
      if (last && x - last.x < 6) last.events.push(e); else stacks.push({ t: e.time_s, x, events: [e] });
    }
    const widthOf = (s) => 10 + 6.2 * Math.max(...s.events.slice(0, MAX_STACK).map((e) => shortEvent(e).length));
    const rowsOf = (s) => Math.min(s.events.length, MAX_STACK) + (s.events.length > MAX_STACK ? 1 : 0);
    // stacks that would still overlap side by side go one block lower
    const ends = [];
    let depth = 1;
    this.eventLane.querySelectorAll(".ev-stack").forEach((n) => n.remove());
    for (const s of stacks) {
      let top = 0;
      for (const [end, from, to] of ends) if (s.x < end + 4 && top < to && from < top + rowsOf(s)) top = to;
      ends.push([s.x + widthOf(s), top, top + rowsOf(s)]);
      depth = Math.max(depth, top + rowsOf(s));
      const more = s.events.length - MAX_STACK;
      const el = h("div", {
        className: "ev-stack", dataset: { t: String(s.t), n: String(s.events.length) },
        title: s.events.map(longEvent).join("\n"), tabIndex: -1,
        style: `left:${s.x}px; top:${top * LANE}px`,
      }, ...s.events.slice(0, MAX_STACK).map((e) => h("span", { className: "ev-label" }, shortEvent(e))),
      more > 0 ? h("span", { className: "ev-label more" }, `+${more} more`) : null);
      el.addEventListener("mouseenter", () => this._showTip(s, el));
      el.addEventListener("mouseleave", () => { this.tip.hidden = true; });
      el.addEventListener("click", () => this.onSeek(s.t));
      this.eventLane.append(el);
    }
    this.eventLane.style.height = `${depth * LANE + 2}px`;
  }

  _showTip(stack, el) {
    this.tip.replaceChildren(...stack.events.map((e) => h("div", {}, longEvent(e))));
    this.tip.hidden = false;
    const left = Math.min(el.offsetLeft, this.area.clientWidth - this.tip.offsetWidth - 4);
    this.tip.style.left = `${Math.max(0, left)}px`;
    this.tip.style.top = `${el.offsetTop + el.offsetHeight + this.eventLane.offsetTop + 2}px`;
  }

  draw() {
    if (!this.ev) return;
    const c = this.canvas, dpr = window.devicePixelRatio || 1;
    const w = this.area.clientWidth || 600, H = ROWS.reduce((a, r) => a + r.h + GAP, GAP);
    // the label lanes are DOM: rebuilt when the width or the markers change, not per frame
    const lanes = `${w}|${this.markers.map((m) => m.t).join(",")}`;
    if (lanes !== this._lanes) { this._lanes = lanes; this._drawMarkerLane(w); this._drawEventLane(w); }
    c.style.height = `${H}px`;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(H * dpr)) { c.width = Math.round(w * dpr); c.height = Math.round(H * dpr); }
    const g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, H);
    g.font = `11px ${getComputedStyle(c).fontFamily}`;
    let y = GAP;
    const ev = this.ev, ts = ev.time_s;
    for (const row of ROWS) {
      g.fillStyle = "#f8fafc"; g.fillRect(GUTTER, y, w - GUTTER - RIGHT, row.h);
      g.fillStyle = "#475569"; g.textBaseline = "middle"; g.fillText(row.label, 4, y + row.h / 2);
      const series = (vals, max) => vals.map((v, i) => v == null ? null
        : [this.x(ts[i], w), y + row.h - 2 - (row.h - 4) * Math.min(1, v / max)]);
      const line = (vals, max, color, width) => {
        g.strokeStyle = color; g.lineWidth = width; g.setLineDash([]); g.beginPath();
        let started = false;
        for (const p of series(vals, max)) { if (!p) continue; if (!started) { g.moveTo(...p); started = true; } else g.lineTo(...p); }
        g.stroke();
      };
      const area = (vals, max, color) => {
        const pts = series(vals, max).filter(Boolean);
        if (!pts.length) return;
        g.fillStyle = color; g.beginPath(); g.moveTo(pts[0][0], y + row.h);
        for (const p of pts) g.lineTo(...p);
        g.lineTo(pts[pts.length - 1][0], y + row.h); g.closePath(); g.fill();
      };
      if (row.key === "phases" && this.phases) {
        for (const [name, [a, b]] of Object.entries(this.phases)) {
          const x0 = this.x(a / this.hz, w), x1 = this.x(b / this.hz, w);
          g.fillStyle = PHASE_COLORS[name] || "#eee"; g.fillRect(x0, y, x1 - x0, row.h);
          g.fillStyle = "#334155"; if (x1 - x0 > 34) g.fillText(name, x0 + 4, y + row.h / 2);
        }
      }
      if (row.key === "phases") {  // event ticks, labelled in the lane above
        g.fillStyle = EVENT;
        for (const e of this.events) {
          const px = this.x(e.time_s, w);
          g.beginPath(); g.moveTo(px - 4, y); g.lineTo(px + 4, y); g.lineTo(px, y + 7); g.fill();
        }
      }
      if (row.key === "gripper") area(ev.gripper_opening, this.maxGrip, FILLS.gripper);
      if (row.key === "goal") area(ev.goal_progress, 1, FILLS.goal);
      if (row.key === "disp") {
        const targets = new Set(ev.targets || []);
        for (const o of this.objects) line(ev.displacement[o], this.maxDisp, this.colors[o], targets.has(o) ? 2.5 : 1.4);
        g.fillStyle = "#64748b"; g.fillText(`${(this.maxDisp * 100).toFixed(0)} cm`, GUTTER + 3, y + 7);
      }
      if (row.key === "grasp" || row.key === "contacts") {
        // one bar per run of equal values (no seams between steps)
        const val = (i) => row.key === "grasp" ? (ev.grasped[i] || "")
          : ((ev.contacts[i] || []).some((p) => !p.includes("table")) ? "contact" : "");
        for (let i = 0; i < ts.length;) {
          let j = i;
          while (j + 1 < ts.length && val(j + 1) === val(i)) j++;
          if (val(i)) {
            const x0 = this.x(ts[i], w), x1 = this.x(ts[Math.min(ts.length - 1, j + 1)], w);
            g.fillStyle = row.key === "grasp" ? (this.colors[val(i)] || FILLS.contacts) : FILLS.contacts;
            g.fillRect(x0, y + 2, Math.max(1, x1 - x0), row.h - 4);
          }
          i = j + 1;
        }
      }
      y += row.h + GAP;
    }
    // time markers across every row, in their line styles
    for (const m of this.markers) {
      if (m.t == null) continue;
      const s = this.style(m), px = this.x(m.t, w);
      g.strokeStyle = s.color; g.lineWidth = s.width; g.setLineDash(s.dash);
      g.beginPath(); g.moveTo(px, 0); g.lineTo(px, H); g.stroke();
    }
    g.setLineDash([]);
    const px = this.x(this.t, w);
    g.strokeStyle = PLAYHEAD; g.lineWidth = 1;
    g.beginPath(); g.moveTo(px, 0); g.lineTo(px, H); g.stroke();
    g.fillStyle = PLAYHEAD;
    g.beginPath(); g.moveTo(px - 5, 0); g.lineTo(px + 5, 0); g.lineTo(px, 6); g.fill();
    g.beginPath(); g.moveTo(px - 5, H); g.lineTo(px + 5, H); g.lineTo(px, H - 6); g.fill();
  }

  updateReadout() {
    if (!this.ev) return;
    const i = this.index(this.t), ev = this.ev;
    const contacts = (ev.contacts[i] || []).filter((p) => !p.includes("table"));
    const near = this.events.filter((e) => Math.abs(e.time_s - ev.time_s[i]) < 0.25);
    // two lines at most (the panel keeps its height as the playhead moves); the whole text
    // is in the tooltip
    this.readout.replaceChildren(...[
      near.length ? h("span", { className: "event-now" }, h("b", {}, "event "), near.map((e) =>
        `${e.kind}${e.object ? ` (${e.object})` : ""}`).join(", ")) : null,
      h("span", {}, h("b", {}, "t "), `${ev.time_s[i].toFixed(2)} s (step ${ev.step[i]})`),
      h("span", {}, h("b", {}, "gripper "), `${(ev.gripper_opening[i] * 100).toFixed(1)} cm`),
      h("span", {}, h("b", {}, "grasped "), ev.grasped[i] || "nothing"),
      h("span", {}, h("b", {}, "goal "), `${Math.round(ev.goal_progress[i] * 100)} %`),
      h("span", {}, h("b", {}, "contacts "), contacts.length ? contacts.join(", ") : "none"),
      h("span", {}, h("b", {}, "displacement "), this.objects.map((o) =>
        `${o} ${((ev.displacement[o][i] || 0) * 100).toFixed(1)} cm`).join(" · "))].filter(Boolean));
    this.readout.title = this.readout.innerText;
  }
}
