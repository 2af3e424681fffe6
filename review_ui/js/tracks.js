// Simulator evidence on the video's playhead: one canvas of tracks sharing a time axis
// (phases + events, gripper opening, grasp, contacts, displacement per object, goal
// progress), with the playhead and the model's / reviewers' failure times marked.
// Click or drag anywhere on the tracks to seek.
import { h } from "./dom.js";

const GUTTER = 118;
const ROWS = [
  { key: "phases", label: "phases · events", h: 24 },
  { key: "gripper", label: "gripper opening", h: 46 },
  { key: "grasp", label: "grasp", h: 18 },
  { key: "contacts", label: "contacts", h: 18 },
  { key: "disp", label: "displacement", h: 78 },
  { key: "goal", label: "goal progress", h: 30 },
];
const PALETTE = ["#2563eb", "#d97706", "#059669", "#db2777", "#7c3aed", "#0891b2", "#65a30d", "#dc2626", "#475569"];
const PHASE_COLORS = { pre: "#e7f3e3", during: "#fde0d2", post: "#e5e9f5" };

export class Tracks {
  constructor({ evidence, media, markers = [], onSeek }) {
    this.ev = evidence;
    this.hz = media.control_hz || 20;
    this.phases = media.phases;
    this.events = media.events || [];
    this.markers = markers;
    this.onSeek = onSeek;
    this.t = 0;
    const times = evidence ? evidence.time_s : [];
    this.duration = Math.max(media.duration_s || 0, times.length ? times[times.length - 1] : 0, 0.1);
    this.objects = evidence ? Object.keys(evidence.displacement) : [];
    this.colors = Object.fromEntries(this.objects.map((o, i) => [o, PALETTE[i % PALETTE.length]]));
    this.maxDisp = Math.max(0.02, ...this.objects.flatMap((o) => evidence.displacement[o].filter((x) => x != null)));
    this.maxGrip = Math.max(0.01, ...(evidence ? evidence.gripper_opening : [0]));
    this.canvas = h("canvas", { className: "tracks-canvas", id: "tracks" });
    this.readout = h("div", { className: "ev-readout", id: "ev-readout" });
    const targets = new Set(evidence ? evidence.targets || [] : []);
    const legend = h("div", { className: "legend" },
      ...this.objects.map((o) => h("span", { className: targets.has(o) ? "target" : "" },
        h("i", { style: `background:${this.colors[o]}` }), o, targets.has(o) ? " (target)" : "")),
      ...this.markerLegend());
    this.legendEl = legend;
    this.el = h("div", { className: "tracks" },
      evidence ? this.canvas : h("p", { className: "muted" }, "No simulator evidence for this episode."),
      legend, this.readout);
    this._wire();
  }

  markerLegend() {
    return this.markers.map((m) => h("span", { className: "marker-key" },
      h("i", { style: `background:${m.color}` }), m.label));
  }
  setMarkers(markers) {
    this.markers = markers;
    this.legendEl.querySelectorAll(".marker-key").forEach((n) => n.remove());
    this.legendEl.append(...this.markerLegend());
    this.draw();
  }
  setPlayhead(t) { this.t = t; this.draw(); this.updateReadout(); }

  x(t, w) { return GUTTER + (w - GUTTER - 8) * Math.min(1, Math.max(0, t / this.duration)); }
  tAt(px, w) { return Math.min(this.duration, Math.max(0, (px - GUTTER) / (w - GUTTER - 8) * this.duration)); }
  index(t) {
    const ts = this.ev.time_s;
    let lo = 0, hi = ts.length - 1;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (ts[mid] < t) lo = mid + 1; else hi = mid; }
    return lo > 0 && Math.abs(ts[lo - 1] - t) < Math.abs(ts[lo] - t) ? lo - 1 : lo;
  }

  _wire() {
    if (!this.ev) return;
    const seek = (e) => {
      const r = this.canvas.getBoundingClientRect();
      if (e.clientX - r.left < GUTTER) return;
      this.onSeek(this.tAt(e.clientX - r.left, r.width));
    };
    let dragging = false;
    this.canvas.addEventListener("pointerdown", (e) => { dragging = true; this.canvas.setPointerCapture(e.pointerId); seek(e); });
    this.canvas.addEventListener("pointermove", (e) => { if (dragging) seek(e); });
    this.canvas.addEventListener("pointerup", () => { dragging = false; });
    new ResizeObserver(() => this.draw()).observe(this.canvas);
  }

  draw() {
    if (!this.ev) return;
    const c = this.canvas, dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth || 600, H = ROWS.reduce((a, r) => a + r.h + 6, 4 + 12 * Math.max(1, this.markers.length));
    c.style.height = `${H}px`;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(H * dpr)) { c.width = Math.round(w * dpr); c.height = Math.round(H * dpr); }
    const g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, H);
    g.font = "11px system-ui, sans-serif";
    let y = 2;
    const ev = this.ev, ts = ev.time_s;
    for (const row of ROWS) {
      g.fillStyle = "#f8fafc"; g.fillRect(GUTTER, y, w - GUTTER - 8, row.h);
      g.fillStyle = "#475569"; g.textBaseline = "middle"; g.fillText(row.label, 6, y + row.h / 2);
      const line = (vals, max, color, width = 1.5) => {
        g.strokeStyle = color; g.lineWidth = width; g.beginPath();
        let started = false;
        vals.forEach((v, i) => {
          if (v == null) return;
          const px = this.x(ts[i], w), py = y + row.h - 3 - (row.h - 6) * Math.min(1, v / max);
          if (!started) { g.moveTo(px, py); started = true; } else g.lineTo(px, py);
        });
        g.stroke();
      };
      if (row.key === "phases" && this.phases) {
        for (const [name, [a, b]] of Object.entries(this.phases)) {
          const x0 = this.x(a / this.hz, w), x1 = this.x(b / this.hz, w);
          g.fillStyle = PHASE_COLORS[name] || "#eee"; g.fillRect(x0, y, x1 - x0, row.h);
          g.fillStyle = "#334155"; if (x1 - x0 > 34) g.fillText(name, x0 + 4, y + row.h / 2);
        }
      }
      if (row.key === "phases") {
        g.fillStyle = "#b91c1c";
        for (const e of this.events) {
          const px = this.x(e.time_s, w);
          g.beginPath(); g.moveTo(px - 4, y + row.h); g.lineTo(px + 4, y + row.h); g.lineTo(px, y + row.h - 8); g.fill();
        }
      }
      if (row.key === "gripper") line(ev.gripper_opening, this.maxGrip, "#0f172a");
      if (row.key === "goal") line(ev.goal_progress, 1, "#16a34a");
      if (row.key === "disp") {
        const targets = new Set(ev.targets || []);
        for (const o of this.objects) line(ev.displacement[o], this.maxDisp, this.colors[o], targets.has(o) ? 2.5 : 1.3);
        g.fillStyle = "#64748b"; g.fillText(`${(this.maxDisp * 100).toFixed(0)} cm`, GUTTER + 3, y + 7);
      }
      if (row.key === "grasp" || row.key === "contacts") {
        ts.forEach((t, i) => {
          const on = row.key === "grasp" ? ev.grasped[i] : (ev.contacts[i] || []).filter((p) => !p.includes("table")).length;
          if (!on) return;
          const x0 = this.x(t, w), x1 = this.x(ts[Math.min(ts.length - 1, i + 1)], w);
          g.fillStyle = row.key === "grasp" ? (this.colors[ev.grasped[i]] || "#2563eb") : "#f59e0b";
          g.fillRect(x0, y + 3, Math.max(1, x1 - x0), row.h - 6);
        });
      }
      y += row.h + 6;
    }
    // markers and playhead across all rows
    this.markers.forEach((m, k) => {
      if (m.t == null) return;
      const px = this.x(m.t, w);
      g.strokeStyle = m.color; g.lineWidth = 2; g.setLineDash(m.dash ? [5, 3] : []);
      g.beginPath(); g.moveTo(px, 0); g.lineTo(px, y); g.stroke();
      // labels stacked below the tracks so markers at the same time stay readable
      g.setLineDash([]); g.fillStyle = m.color; g.fillText(m.short || m.label, px + 3, y + 6 + 12 * k);
    });
    const px = this.x(this.t, w);
    g.strokeStyle = "#0f172a"; g.lineWidth = 1.5;
    g.beginPath(); g.moveTo(px, 0); g.lineTo(px, y); g.stroke();
    g.fillStyle = "#0f172a"; g.beginPath(); g.moveTo(px - 5, 0); g.lineTo(px + 5, 0); g.lineTo(px, 7); g.fill();
  }

  updateReadout() {
    if (!this.ev) return;
    const i = this.index(this.t), ev = this.ev;
    const contacts = (ev.contacts[i] || []).filter((p) => !p.includes("table"));
    const near = this.events.filter((e) => Math.abs(e.time_s - ev.time_s[i]) < 0.25);
    this.readout.replaceChildren(...[
      h("div", {}, h("b", {}, "t "), `${ev.time_s[i].toFixed(2)} s (step ${ev.step[i]})`),
      h("div", {}, h("b", {}, "gripper "), `${(ev.gripper_opening[i] * 100).toFixed(1)} cm`),
      h("div", {}, h("b", {}, "grasped "), ev.grasped[i] || "nothing"),
      h("div", {}, h("b", {}, "contacts "), contacts.length ? contacts.join(", ") : "none"),
      h("div", {}, h("b", {}, "displacement "), this.objects.map((o) =>
        `${o} ${((ev.displacement[o][i] || 0) * 100).toFixed(1)} cm`).join(" · ")),
      h("div", {}, h("b", {}, "goal "), `${Math.round(ev.goal_progress[i] * 100)} %`),
      near.length ? h("div", { className: "event-now" }, h("b", {}, "event "), near.map((e) =>
        `${e.kind}${e.object ? ` (${e.object})` : ""}`).join(", ")) : null].filter(Boolean));
  }
}
