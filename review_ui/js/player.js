// Video player on the control grid: the playhead is a simulator time, stepped one control
// step (1/control_hz, 0.05 s at 20 Hz) at a time; the videos show the rendered frame nearest
// to it (review videos are rendered at a few fps, so several steps share one frame). Jumping
// to the model's time puts the playhead exactly there, so T then stores exactly that time.
// Both cameras side by side; V shows one at a time (both, then each alone).
import { h } from "./dom.js";

export const SPEEDS = [0.1, 0.25, 0.5, 0.75, 1, 1.5, 2];
export const BIG_STEP = 10;
const CAMERA_NAMES = { agentview: "agentview", robot0_eye_in_hand: "wrist camera" };
const EPS = 1e-6;

// [{name, url}] from the item payload: `media.cameras` (every review camera, url null where
// the episode has none) or, from older servers, the `media.videos` map
export function cameraList(media) {
  const list = media.cameras || Object.entries(media.videos || {}).map(([name, url]) => ({ name, url }));
  return list.filter((c) => c.url).sort((a, b) => (b.name === "agentview") - (a.name === "agentview"));
}

export class Player {
  constructor(media, frames, { onTick, modelTime }) {
    this.fps = media.fps || 10;
    this.hz = media.control_hz || 20;
    this.frames = frames && frames.time_s && frames.time_s.length ? frames : null;
    this.onTick = onTick || (() => {});
    this.modelTime = modelTime;
    this.t = 0;  // the playhead (s): on the control grid, or exactly the model's time after M
    this.duration = media.duration_s ?? (this.frames ? this.frames.time_s[this.frames.time_s.length - 1] : null);
    const cams = cameraList(media);  // agentview first: it drives the clock
    this.videos = cams.map((c) => {
      const v = h("video", { muted: true, playsInline: true, preload: "auto", src: c.url });
      v.id = c === cams[0] ? "video-main" : c.name === "robot0_eye_in_hand" ? "video-wrist" : `video-${c.name}`;
      return v;
    });
    this.main = this.videos[0] || h("video", { id: "video-main" });
    this.wrist = this.videos.find((v) => v.id === "video-wrist") || null;
    this.readout = h("span", { className: "readout", id: "readout" }, "loading video…");
    this.playBtn = h("button", { type: "button", id: "btn-play", onclick: () => this.toggle() }, "▶ Play ", h("kbd", {}, "Space"));
    this.speed = h("select", { id: "speed", title: "playback speed", onchange: () => this.setRate(+this.speed.value) },
      ...SPEEDS.map((s) => h("option", { value: String(s), selected: s === 1 }, `${s}×`)));
    const stepBtn = (n, label, key) => h("button", { type: "button", className: "step", id: `btn-step${n > 0 ? "+" : ""}${n}`,
      title: `${Math.abs(n)} control step${Math.abs(n) > 1 ? "s" : ""} (${(Math.abs(n) / this.hz).toFixed(2)} s)`,
      onclick: () => this.step(n) }, label, " ", h("kbd", {}, key));
    const controls = h("div", { className: "controls" },
      this.playBtn,
      stepBtn(-BIG_STEP, `−${BIG_STEP}`, "⇧←"), stepBtn(-1, "−1", "←"), stepBtn(1, "+1", "→"), stepBtn(BIG_STEP, `+${BIG_STEP}`, "⇧→"),
      h("label", { className: "speed" }, this.speed, " ", h("kbd", {}, "["), h("kbd", {}, "]")),
      modelTime != null ? h("button", { type: "button", id: "btn-jump-model", onclick: () => this.seekTime(modelTime) },
        "Model ", h("kbd", {}, "M")) : null,
      cams.length > 1 ? h("button", { type: "button", id: "btn-camera", title: "both cameras / one at a time", onclick: () => this.cycleView() },
        "View ", h("kbd", {}, "V")) : null,
      this.readout);
    const fig = (v, c) => h("figure", { dataset: { camera: c.name } }, v, h("figcaption", {}, CAMERA_NAMES[c.name] || c.name));
    this.view = 0;  // 0: every camera; k: camera k-1 alone
    this.videoBox = h("div", { className: `videos n${Math.max(1, cams.length)}`, id: "videos" },
      ...(cams.length ? cams.map((c, i) => fig(this.videos[i], c)) : [h("div", { className: "novideo" }, "no video for this episode")]));
    this.el = h("div", { className: "player" }, this.videoBox, controls);
    this._wire();
  }

  get nFrames() {
    if (this.frames) return this.frames.time_s.length;
    return Math.max(1, Math.round((this.main.duration || 0) * this.fps));
  }
  get end() { return this.duration ?? (this.nFrames - 1) / this.fps; }
  // the video frame showing now, and the simulator time of a frame
  frame() { return Math.min(this.nFrames - 1, Math.max(0, Math.floor(this.main.currentTime * this.fps + 1e-3))); }
  simTimeOfFrame(i) { return this.frames ? this.frames.time_s[i] : i / this.fps; }
  stepOfFrame(i) { return this.frames ? this.frames.step[i] : Math.round(this.simTimeOfFrame(i) * this.hz); }
  // the simulator time shown by the video now (continuous while playing)
  videoSimTime() {
    const x = this.main.currentTime * this.fps;
    if (!this.frames) return Math.max(0, this.main.currentTime - 0.5 / this.fps);  // frame i shows i/fps
    const i = Math.min(this.nFrames - 1, Math.floor(x)), j = Math.min(this.nFrames - 1, i + 1);
    const a = this.frames.time_s[i], b = this.frames.time_s[j];
    return a + (b - a) * Math.min(1, Math.max(0, x - i - 0.5));
  }
  playing() { return !this.main.paused; }
  // the playhead: the paused control-grid time, or the video's time while playing
  time() { return this.playing() ? this.videoSimTime() : this.t; }
  controlStep() { return Math.round(this.t * this.hz); }
  frameForSim(t) {
    if (!this.frames) return Math.min(this.nFrames - 1, Math.max(0, Math.round(t * this.fps)));
    const ts = this.frames.time_s;
    let best = 0;
    for (let i = 1; i < ts.length; i++) if (Math.abs(ts[i] - t) < Math.abs(ts[best] - t) - EPS) best = i;
    return best;
  }

  // put the playhead at `t` exactly (clamped to the episode) and show the nearest frame
  seekTime(t) {
    this.pause(false);
    this.t = Math.min(this.end, Math.max(0, t));
    this._show(this.frameForSim(this.t));
  }
  // a time on the grid: the nearest control step
  seekGrid(t) { this.seekTime(Math.round(t * this.hz) / this.hz); }
  seekFrame(i) { this.seekTime(this.simTimeOfFrame(Math.min(this.nFrames - 1, Math.max(0, i)))); }
  // n control steps from the playhead; from an off-grid time the first step lands on the grid
  step(n) {
    if (this.playing()) this.pause();
    const x = this.t * this.hz;
    const s = n > 0 ? Math.floor(x + EPS) + n : Math.ceil(x - EPS) + n;
    this.seekTime(Math.min(Math.floor(this.end * this.hz + EPS), Math.max(0, s)) / this.hz);
  }
  _show(i) {
    const at = (i + 0.5) / this.fps;  // the middle of the frame's display interval: exactly that frame
    for (const v of this.videos) if (Math.abs(v.currentTime - at) > 1e-4) v.currentTime = at;
    this._tick();
  }
  toggle() { this.playing() ? this.pause() : this.play(); }
  play() {
    if (this.main.ended || this.t >= this.end - EPS) this.main.currentTime = 0;
    else this.main.currentTime = (this.frameForSim(this.t) + 0.5) / this.fps;
    for (const v of this.videos) { v.currentTime = this.main.currentTime; v.play().catch(() => {}); }
  }
  // pausing after play puts the playhead on the control step nearest to what is shown
  pause(snap = true) {
    const wasPlaying = this.playing();
    for (const v of this.videos) v.pause();
    if (snap && wasPlaying) this.seekGrid(this.videoSimTime());
  }
  setRate(r) {
    for (const v of this.videos) v.playbackRate = r;
    this.speed.value = String(r);
    this._tick();
  }
  faster(dir) {
    const i = SPEEDS.indexOf(this.main.playbackRate);
    const j = Math.min(SPEEDS.length - 1, Math.max(0, (i < 0 ? SPEEDS.indexOf(1) : i) + dir));
    this.setRate(SPEEDS[j]);
  }
  cycleView() {
    const figs = [...this.videoBox.querySelectorAll("figure")];
    if (figs.length < 2) return;
    this.view = (this.view + 1) % (figs.length + 1);
    figs.forEach((f, k) => { f.hidden = this.view !== 0 && this.view !== k + 1; });
    this.videoBox.classList.toggle("single", this.view !== 0);
    this.videoBox.dataset.view = this.view === 0 ? "all" : figs[this.view - 1].dataset.camera;
  }

  _wire() {
    const v = this.main;
    const loop = () => {
      this._tick();
      for (const o of this.videos) if (o !== v && Math.abs(o.currentTime - v.currentTime) > 0.08) o.currentTime = v.currentTime;
      if (!v.paused) this._raf = requestAnimationFrame(loop);
    };
    v.addEventListener("play", () => { this.playBtn.firstChild.textContent = "❚❚ Pause "; this.el.classList.add("playing"); loop(); });
    v.addEventListener("pause", () => { this.playBtn.firstChild.textContent = "▶ Play "; this.el.classList.remove("playing"); this._tick(); });
    v.addEventListener("ended", () => this.seekTime(this.end));
    for (const ev of ["loadedmetadata", "seeked"]) v.addEventListener(ev, () => this._tick());
    v.addEventListener("error", () => { this.readout.textContent = "the video could not be loaded"; this.readout.classList.add("error"); });
  }

  _tick() {
    const i = this.playing() ? this.frame() : this.frameForSim(this.t);
    const t = this.time();
    this.readout.textContent = `${t.toFixed(2)} s · step ${Math.round(t * this.hz)} · frame ${i + 1}/${this.nFrames}` +
      ` (${this.simTimeOfFrame(i).toFixed(2)} s) · ${this.main.playbackRate}×`;
    this.el.dataset.frame = String(i);
    this.el.dataset.step = String(Math.round(t * this.hz));
    this.el.dataset.time = String(Math.round(t * 1e6) / 1e6);
    this.onTick(this);
  }

  destroy() {
    cancelAnimationFrame(this._raf);
    for (const v of this.videos) { v.pause(); v.removeAttribute("src"); v.load(); }
  }
}
