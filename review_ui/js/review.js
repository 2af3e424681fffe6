// The item page: video + evidence on one playhead, the model's suggestion, the decision.
// A reviewer sees the model's proposal (as a suggestion, with model and prompt version) and
// never another reviewer's decision (the API does not send them).
import { api, ApiError, newKey } from "./api.js";
import { h } from "./dom.js";
import { FIELD_LABELS, FieldControls, FIELDS, showValue } from "./fields.js";
import { episodeHeader, itemKeys, playerAndTracks, playheadTime, versionLine } from "./item_common.js";


export async function reviewPage(root, id, app) {
  const item = await api(`/api/items/${id}`);
  let taken = null;  // the item is full: other reviewers hold every place
  if (item.state === "open" && !item.my_review) {
    try { await api(`/api/items/${id}/lease`, { method: "POST" }); }
    catch (e) { if (!(e instanceof ApiError)) throw e; if (e.status === 409) taken = e.message; }
  }
  const p = item.proposal;
  const open = item.state === "open" && !taken;
  const start = item.my_review && item.my_review.values ? item.my_review.values : p;
  const view = { version: item.version, busy: false, pendingAccept: false };
  const incomplete = FIELDS.some((f) => p[f] == null);  // nothing complete to accept: revise instead

  const media = await playerAndTracks(item, {
    initial: start,
    markers: (values) => [
      { t: p.fail_time_s, label: "model's failure time", short: "model", kind: "model" },
      { t: values.fail_time_s, label: "your failure time", short: "you", kind: "you" },
    ],
  });
  const controls = new FieldControls({
    values: Object.fromEntries(FIELDS.map((f) => [f, start[f] ?? null])),
    suggested: p, choices: item.choices, duration: item.media.duration_s, controlHz: item.media.control_hz || 20,
    getPlayhead: () => playheadTime(media.player),
    onChange: (values) => { media.tracks.setMarkers(media.markers(values)); view.pendingAccept = false; },
  });

  const status = h("div", { className: "decision-status", id: "decision-status" });
  const reason = h("textarea", { id: "flag-reason", rows: 2, placeholder: "why is this ambiguous? (required)" });
  const flagBox = h("div", { className: "flag-box", id: "flag-box", hidden: true }, h("label", { htmlFor: "flag-reason" }, "Reason for the flag"), reason,
    h("button", { type: "button", className: "warn", id: "btn-flag-confirm", onclick: () => submit("flag") }, "Flag as ambiguous ", h("kbd", {}, "Enter")),
    h("p", { className: "field-error", id: "err-reason", hidden: true }));
  reason.addEventListener("keydown", (e) => { if (e.key === "Enter" && !e.shiftKey) { e.preventDefault(); submit("flag"); } });
  const btn = (id, cls, label, key, fn) => h("button", { type: "button", id, className: cls, onclick: fn }, label, " ", h("kbd", {}, key));
  const buttons = h("div", { className: "decision-buttons" },
    btn("btn-accept", "primary", "Accept", "A", () => submit("accept")),
    btn("btn-revise", "secondary", "Revise", "S", () => submit("revise")),
    btn("btn-flag", "warn-outline", "Flag", "F", () => openFlag()),
    btn("btn-next", "ghost", "Next", "N", () => app.next()));
  buttons.querySelector("#btn-accept").title = "accept the model's suggestion";
  buttons.querySelector("#btn-revise").title = "submit your revision (the fields marked edited)";
  buttons.querySelector("#btn-flag").title = "flag as ambiguous (a reason is required)";
  // which buttons work: none while saving; only Next on a closed item; no Accept without a
  // complete suggestion (a quarantined item: the reviewer sets every field and submits)
  function setButtons(busy) {
    buttons.querySelectorAll("button").forEach((b) => {
      b.disabled = busy || (!open && b.id !== "btn-next") || (b.id === "btn-accept" && incomplete);
    });
  }

  function setStatus(kind, text, extra) {
    status.className = `decision-status ${kind}`;
    status.replaceChildren(h("span", {}, text), extra || "");
  }
  function openFlag() { flagBox.hidden = false; reason.focus(); }
  function showMine(r) {
    if (!r) return;
    const what = r.decision === "flag" ? `flagged as ambiguous (“${r.reason}”)` : r.decision === "accept" ? "accepted the suggestion" : `revised ${r.edited.join(", ")}`;
    setStatus("saved", `Your decision: ${what} · version ${r.version}${open ? " · you can still change it" : " · closed"}`);
  }

  async function submit(decision) {
    if (view.busy || !open) return;
    const body = { decision, version: view.version, idempotency_key: newKey() };
    if (decision === "revise") {
      body.fields = controls.edits();
      if (!Object.keys(body.fields).length) {
        return setStatus("error", incomplete
          ? "Nothing is set: the model gave no usable values, so set every field, then press S."
          : "Nothing is edited: change a field, or press A to accept the suggestion.");
      }
    }
    if (decision === "accept" && incomplete) return setStatus("error", "The model proposed no complete values: set every field and press S.");
    if (decision === "accept" && Object.keys(controls.edits()).length && !view.pendingAccept) {
      view.pendingAccept = true;
      return setStatus("warning", "You have edits. Press S to submit them, or A again to discard them and accept the suggestion.");
    }
    if (decision === "flag") {
      if (flagBox.hidden) return openFlag();
      body.reason = reason.value.trim();
    }
    view.busy = true;
    setButtons(true);
    setStatus("busy", "Saving…");
    try {
      const r = await api(`/api/items/${id}/review`, { method: "POST", body });
      view.version = r.version;
      const word = { accept: "Accepted", revise: "Revision saved", flag: "Flagged" }[decision];
      setStatus("saved", `${word}${r.replayed ? " (already saved)" : ""} · version ${r.version}`);
      app.toast(`${word}: item ${id}`);
      setTimeout(() => app.next(), 700);
    } catch (e) {
      if (!(e instanceof ApiError)) throw e;
      if (e.status === 422) {
        if (e.field === "reason") {
          const er = flagBox.querySelector("#err-reason");
          er.hidden = false;
          er.textContent = e.message;
        } else controls.showError(e.field, e.message);
        setStatus("error", `Not saved: ${e.message}`);
      } else if (e.status === 409) {
        setStatus("error", `Not saved: ${e.message}`, h("button", { type: "button", id: "btn-reload", onclick: () => app.route() }, "Reload"));
      } else setStatus("error", `Not saved (${e.status}): ${e.message}`);
    } finally {
      view.busy = false;
      setButtons(false);
    }
  }

  const suggestion = h("section", { className: "card suggestion", id: "suggestion" },
    h("h3", {}, "Model suggestion ", h("span", { className: "pill" }, "suggestion")),
    versionLine(p),
    FIELDS.every((f) => p[f] == null) ? h("p", { className: "muted small" }, "No values proposed.") :
    h("dl", {}, ...FIELDS.flatMap((f) => [h("dt", {}, FIELD_LABELS[f]), h("dd", { dataset: { field: f }, title: f === "recovery_action" ? p[f] || "" : undefined }, showValue(f, p[f]),
      f === "fail_time_s" && p.fail_time_s != null ? h("button", { type: "button", className: "ghost jump", id: "btn-jump-suggested",
        onclick: () => media.player.seekTime(p.fail_time_s) }, "jump ", h("kbd", {}, "M")) : null)])));

  const side = h("aside", { className: "side" },
    taken ? h("div", { className: "banner error", id: "taken-banner" }, taken, " · press ", h("kbd", {}, "N"), " for the next item") : null,
    item.quarantined ? h("div", { className: "banner quarantine", id: "quarantine-banner" },
      h("b", {}, "Quarantined model output"), ` · ${item.quarantine_reason}`,
      item.quarantine_detail ? h("div", { className: "muted" }, item.quarantine_detail) : null,
      h("div", {}, "The model gave no usable values: set every field yourself and submit a revision.")) : null,
    suggestion,
    h("section", { className: "card decision" }, h("h3", {}, "Your decision"), controls.el, flagBox, buttons, status));
  root.replaceChildren(episodeHeader(item), h("div", { className: "item-layout" }, h("div", { className: "stage" }, media.el), side));
  if (!open) controls.disable(true);
  if (incomplete) buttons.querySelector("#btn-accept").title = "the model proposed no complete values";
  setButtons(false);
  showMine(item.my_review);
  media.start();

  return {
    destroy: () => media.destroy(),
    onKey(e) {
      if (itemKeys(e, media, controls, p)) return true;
      const k = e.key.toLowerCase();
      if (k === "a") { submit("accept"); return true; }
      if (k === "s") { submit("revise"); return true; }
      if (k === "f") { openFlag(); return true; }
      if (k === "n") { app.next(); return true; }
      return false;
    },
  };
}
