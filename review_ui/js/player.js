// Video player: frame-exact stepping, speeds 0.1x-2x, the wrist view kept in sync.
// Frame i of the video shows simulator time frames.time_s[i]; we seek to the middle of a
// frame's display interval so the browser shows exactly that frame.
import { h } from "./dom.js";

export const SPEEDS = [0.1, 0.25, 0.5, 0.75, 1, 1.5, 2];
export const BIG_STEP = 10;

export class Player {
  constructor(media, frames, { onTick, modelTime }) {
    this.fps = media.fps || 10;
    this.frames = frames && frames.time_s && frames.time_s.length ? frames : null;
    this.onTick = onTick || (() => {});
    this.modelTime = modelTime;
    const cams = media.videos || {};
    this.main = h("video", { muted: true, playsInline: true, preload: "auto", src: cams.agentview || Object.values(cams)[0] || "" });
    this.main.id = "video-main";
    const wristSrc = cams.robot0_eye_in_hand;
    this.wrist = wristSrc ? h("video", { muted: true, playsInline: true, preload: "auto", src: wristSrc }) : null;
    if (this.wrist) this.wrist.id = "video-wrist";
    this.readout = h("span", { className: "readout", id: "readout" }, "loading video…");
    this.playBtn = h("button", { type: "button", id: "btn-play", onclick: () => this.toggle() }, "▶ Play ", h("kbd", {}, "Space"));
    this.speed = h("select", { id: "speed", title: "playback speed", onchange: () => this.setRate(+this.speed.value) },
      ...SPEEDS.map((s) => h("option", { value: String(s), selected: s === 1 }, `${s}×`)));
    const stepBtn = (n, label, key) => h("button", { type: "button", className: "step", id: `btn-step${n > 0 ? "+" : ""}${n}`,
      onclick: () => this.step(n) }, label, " ", h("kbd", {}, key));
    const controls = h("div", { className: "controls" },
      this.playBtn,
      stepBtn(-BIG_STEP, `−${BIG_STEP}`, "⇧←"), stepBtn(-1, "−1", "←"), stepBtn(1, "+1", "→"), stepBtn(BIG_STEP, `+${BIG_STEP}`, "⇧→"),
      h("label", { className: "speed" }, "Speed ", this.speed, " ", h("kbd", {}, "["), h("kbd", {}, "]")),
      modelTime != null ? h("button", { type: "button", id: "btn-jump-model", onclick: () => this.seekSim(modelTime) },
        "Model time ", h("kbd", {}, "M")) : null,
      this.readout);
    const fig = (v, cap) => h("figure", {}, v, h("figcaption", {}, cap));
    this.el = h("div", { className: "player" },
      h("div", { className: `videos ${this.wrist ? "two" : ""}` },
        cams.agentview || Object.keys(cams).length ? fig(this.main, "agentview") : h("div", { className: "novideo" }, "no video for this episode"),
        this.wrist ? fig(this.wrist, "wrist camera (in sync)") : null),
      controls);
    this._wire();
  }

  get nFrames() {
    if (this.frames) return this.frames.time_s.length;
    return Math.max(1, Math.round((this.main.duration || 0) * this.fps));
  }
  frame() { return Math.min(this.nFrames - 1, Math.max(0, Math.floor(this.main.currentTime * this.fps + 1e-3))); }
  simTimeOfFrame(i) { return this.frames ? this.frames.time_s[i] : i / this.fps; }
  stepOfFrame(i) { return this.frames ? this.frames.step[i] : null; }
  // the simulator time shown now (continuous while playing, for the playhead)
  simTime() {
    const x = this.main.currentTime * this.fps;
    if (!this.frames) return this.main.currentTime;
    const i = Math.min(this.nFrames - 1, Math.floor(x)), j = Math.min(this.nFrames - 1, i + 1);
    const a = this.frames.time_s[i], b = this.frames.time_s[j];
    return a + (b - a) * Math.min(1, Math.max(0, x - i));
  }
  frameForSim(t) {
    if (!this.frames) return Math.round(t * this.fps);
    let best = 0;
    this.frames.time_s.forEach((v, i) => { if (Math.abs(v - t) < Math.abs(this.frames.time_s[best] - t)) best = i; });
    return best;
  }

  seekFrame(i) {
    i = Math.min(this.nFrames - 1, Math.max(0, i));
    this.pause();
    this.main.currentTime = (i + 0.5) / this.fps;
    if (this.wrist) this.wrist.currentTime = this.main.currentTime;
    this._tick();
  }
  seekSim(t) { this.seekFrame(this.frameForSim(t)); }
  step(n) { this.seekFrame(this.frame() + n); }
  toggle() { this.main.paused ? this.play() : this.pause(); }
  play() {
    if (this.main.ended || this.frame() >= this.nFrames - 1) this.main.currentTime = 0;
    this.main.play().catch(() => {});
    if (this.wrist) { this.wrist.currentTime = this.main.currentTime; this.wrist.play().catch(() => {}); }
  }
  pause() {
    this.main.pause();
    if (this.wrist) { this.wrist.pause(); this.wrist.currentTime = this.main.currentTime; }
  }
  setRate(r) {
    this.main.playbackRate = r;
    if (this.wrist) this.wrist.playbackRate = r;
    this.speed.value = String(r);
    this._tick();
  }
  faster(dir) {
    const i = SPEEDS.indexOf(this.main.playbackRate);
    const j = Math.min(SPEEDS.length - 1, Math.max(0, (i < 0 ? SPEEDS.indexOf(1) : i) + dir));
    this.setRate(SPEEDS[j]);
  }

  _wire() {
    const v = this.main;
    const loop = () => {
      this._tick();
      if (this.wrist && Math.abs(this.wrist.currentTime - v.currentTime) > 0.08) this.wrist.currentTime = v.currentTime;
      if (!v.paused) this._raf = requestAnimationFrame(loop);
    };
    v.addEventListener("play", () => { this.playBtn.firstChild.textContent = "❚❚ Pause "; this.el.classList.add("playing"); loop(); });
    v.addEventListener("pause", () => { this.playBtn.firstChild.textContent = "▶ Play "; this.el.classList.remove("playing"); this._tick(); });
    v.addEventListener("ended", () => this.pause());
    for (const ev of ["loadedmetadata", "seeked", "timeupdate"]) v.addEventListener(ev, () => this._tick());
    v.addEventListener("error", () => { this.readout.textContent = "the video could not be loaded"; this.readout.classList.add("error"); });
  }

  _tick() {
    const i = this.frame();
    const step = this.stepOfFrame(i);
    this.readout.textContent = `frame ${i + 1}/${this.nFrames} · ${this.simTimeOfFrame(i).toFixed(2)} s` +
      (step != null ? ` · step ${step}` : "") + ` · ${this.main.playbackRate}×`;
    this.el.dataset.frame = String(i);
    this.onTick(this);
  }

  destroy() {
    cancelAnimationFrame(this._raf);
    for (const v of [this.main, this.wrist]) if (v) { v.pause(); v.removeAttribute("src"); v.load(); }
  }
}
