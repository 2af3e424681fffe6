// Pieces both item pages share: the episode header, video + evidence on one playhead,
// the keys for video and field values.
import { api } from "./api.js";
import { CATEGORY_KEYS, h } from "./dom.js";
import { Player } from "./player.js";
import { Tracks } from "./tracks.js";

export function episodeHeader(item) {
  return h("header", { className: "episode" },
    h("div", { className: "instruction", id: "instruction" }, "“", item.instruction, "”"),
    h("div", { className: "muted key" }, `${item.key} · revision ${item.revision}`,
      item.quarantined ? h("span", { className: "pill quarantine" }, "quarantined") : null));
}

export function versionLine(p) {
  const loc = p.localizer || {}, ch = p.characterizer || {};
  const v = (x) => [x.model || x.source, x.prompt_name ? `${x.prompt_name}${x.prompt_hash ? `@${x.prompt_hash.slice(0, 8)}` : ""}` : null]
    .filter(Boolean).join(" · ") || "—";
  return h("div", { className: "version", id: "model-version" },
    h("span", {}, h("b", {}, "time by "), v(loc)), " · ", h("span", {}, h("b", {}, "labels by "), v(ch)));
}

// video + evidence tracks kept on one playhead; `markers(values)` gives the time markers,
// first for the `initial` values of the fields
export async function playerAndTracks(item, { markers, initial }) {
  const [frames, evidence] = await Promise.all([
    item.media.has_frames ? api(`/api/items/${item.id}/frames`) : null,
    item.media.has_evidence ? api(`/api/items/${item.id}/evidence`) : null,
  ]);
  let tracks = null;
  const player = new Player(item.media, frames, {
    modelTime: item.proposal.fail_time_s,
    onTick: (pl) => { if (tracks) tracks.setPlayhead(pl.time()); },
  });
  tracks = new Tracks({
    evidence, media: item.media, markers: markers(initial),
    onSeek: (t) => player.seekGrid(t),
  });
  const el = h("div", { className: "media" }, player.el, tracks.el);
  return {
    el, player, tracks, markers,
    start: () => { tracks.draw(); tracks.updateReadout(); },
    destroy: () => player.destroy(),
  };
}

// the playhead for T: paused, it is on the control grid (or exactly at the model's time)
export function playheadTime(player) {
  if (player.playing()) player.pause();
  return Math.round(player.time() * 1e6) / 1e6;
}

// returns true when the key was a video key
export function mediaKeys(e, player) {
  const big = e.shiftKey ? 10 : 1;
  switch (e.key) {
    case " ": player.toggle(); return true;
    case "ArrowLeft": case ",": player.step(-big); return true;
    case "ArrowRight": case ".": player.step(big); return true;
    case "[": player.faster(-1); return true;
    case "]": player.faster(1); return true;
    case "Home": player.seekTime(0); return true;
    case "End": player.seekTime(player.end); return true;
    case "v": case "V": player.cycleView(); return true;
    default: return false;
  }
}

const CATEGORY_BY_KEY = Object.fromEntries(Object.entries(CATEGORY_KEYS).map(([c, k]) => [k.toLowerCase(), c]));

// the keys shared by the review and adjudication pages: video, model time, field values;
// returns true when the key was handled
export function itemKeys(e, media, controls, proposal) {
  if (mediaKeys(e, media.player)) return true;
  const k = e.key.toLowerCase();
  // exactly the model's time (not the nearest frame), so T then sets exactly that time
  if (k === "m" && proposal.fail_time_s != null) { media.player.seekTime(proposal.fail_time_s); return true; }
  if (k === "t") { controls.setTimeAtPlayhead(); return true; }
  if (["1", "2", "3", "4"].includes(k)) { controls.set("recovery_level", `L${k}`); return true; }
  if (CATEGORY_BY_KEY[k]) { controls.set("failure_category", CATEGORY_BY_KEY[k]); return true; }
  return false;
}
