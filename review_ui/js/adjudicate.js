// The adjudication page: per field, the model's and every reviewer's value side by side;
// only the disputed fields are decided here, with a required rationale.
import { api, ApiError, newKey } from "./api.js";
import { h } from "./dom.js";
import { FieldControls, FIELD_LABELS, FIELDS, same, showValue } from "./fields.js";
import { dashCss, reviewerMarker } from "./colors.js";
import { episodeHeader, itemKeys, playerAndTracks, playheadTime, versionLine } from "./item_common.js";

export async function adjudicatePage(root, id, app) {
  let item = await api(`/api/items/${id}/adjudication`);
  let claimError = null;
  if (item.status === "conflict" || item.status === "adjudicating") {
    try { item.version = (await api(`/api/items/${id}/claim`, { method: "POST" })).version; }
    catch (e) { if (!(e instanceof ApiError)) throw e; claimError = e.message; }
  }
  const p = item.proposal;
  const disputed = item.disputed;
  const decidable = !claimError && (item.status === "conflict" || item.status === "adjudicating");
  const media = await playerAndTracks(item, {
    initial: {},  // nothing decided yet
    markers: (values) => [
      { t: p.fail_time_s, label: "model", short: "model", kind: "model" },
      ...item.reviews.map((r, i) => ({ t: r.values ? r.values.fail_time_s : null, label: r.reviewer, short: r.reviewer,
        kind: "reviewer", style: reviewerMarker(i) })),
      { t: disputed.includes("fail_time_s") ? values.fail_time_s : item.agreed.fail_time_s,
        label: "your decision", short: "final", kind: "final" },
    ],
  });
  const controls = new FieldControls({
    fields: disputed, values: {}, suggested: p, choices: item.choices, duration: item.media.duration_s,
    controlHz: item.media.control_hz || 20, getPlayhead: () => playheadTime(media.player),
    onChange: (values) => media.tracks.setMarkers(media.markers(values)),
  });

  // one line per field (each value whole in its tooltip) so that the table,
  // the decision panel and the history fit beside the video without scrolling at 1366x768
  const short = (f, v) => (f === "recovery_level" && v != null ? v : showValue(f, v));  // the names are below
  const cell = (f, v) => h("td", { dataset: { field: f }, title: String(showValue(f, v)) },
    h("div", { className: "cv" }, h("span", { className: "val" }, short(f, v)), useBtn(f, v)));
  const useBtn = (f, v) => (decidable && disputed.includes(f) && v != null)
    ? h("button", { type: "button", className: "use", title: "use this value", onclick: () => controls.set(f, v) }, "use") : null;
  const table = h("table", { className: "compare", id: "compare" },
    h("thead", {}, h("tr", {}, h("th", {}, "field"), h("th", { title: "the model's suggestion" }, "model"),
      ...item.reviews.map((r, i) => h("th", {}, h("i", { className: "line", style: `background:${dashCss(reviewerMarker(i))}` }), r.reviewer,
        h("span", { className: "muted" }, ` · ${r.decision}`))))),
    h("tbody", {}, ...FIELDS.map((f) => disputed.includes(f)
      ? h("tr", { className: "disputed", dataset: { field: f } },
        h("th", { title: "disputed: the reviewers differ" }, FIELD_LABELS[f], h("span", { className: "sr" }, " (disputed)")),
        cell(f, p[f]),
        ...item.reviews.map((r) => r.values ? cell(f, r.values[f])
          : h("td", { className: "flagged", title: r.reason }, h("div", { className: "cv" },
            h("span", { className: "val" }, "flagged: ", h("q", {}, r.reason))))))
      // an agreed field: the model's and the common value on one line (the reviewers agree)
      : h("tr", { className: "agreed", dataset: { field: f } }, h("th", {}, FIELD_LABELS[f]),
        h("td", { colSpan: item.reviews.length + 1 }, h("div", { className: "cv" }, h("span", { className: "val" },
          h("span", { className: "muted" }, "model "), showValue(f, p[f]),
          same(f, p[f], item.agreed[f], item.media.control_hz || 20) ? null
            : h("span", {}, h("span", { className: "muted" }, " · reviewers "), showValue(f, item.agreed[f]))),
          h("span", { className: "pill ok" }, "agreed")))))));

  const rationale = h("textarea", { id: "rationale", rows: 2, "aria-label": "Rationale",
    placeholder: "Rationale: why this outcome (required; kept in the audit log)",
    oninput: () => { rationale.classList.remove("invalid"); if (status.classList.contains("error")) setStatus("", ""); } });
  const exclude = h("input", { type: "checkbox", id: "exclude" });
  const status = h("div", { className: "decision-status", id: "adjudication-status" });
  const setStatus = (kind, text, extra) => { status.className = `decision-status ${kind}`; status.replaceChildren(h("span", {}, text), extra || ""); };
  let busy = false;

  async function submit() {
    if (busy || !decidable) return;
    const body = { fields: exclude.checked ? {} : controls.values, rationale: rationale.value, exclude: exclude.checked,
      version: item.version, idempotency_key: newKey() };
    body.fields = Object.fromEntries(Object.entries(body.fields).filter(([, v]) => v != null && v !== ""));
    busy = true;
    setStatus("busy", "Saving…");
    try {
      const r = await api(`/api/items/${id}/adjudication`, { method: "POST", body });
      setStatus("saved", `Final (${r.resolution})${r.replayed ? " · already saved" : ""}`);
      app.toast(`Adjudicated item ${id}: final`);
      setTimeout(() => app.go("#/queue"), 800);
    } catch (e) {
      if (!(e instanceof ApiError)) throw e;
      if (e.status === 422 && e.field === "rationale") rationale.classList.add("invalid");
      else if (e.status === 422) controls.showError(e.field, e.message);
      setStatus("error", `Not saved (${e.status}): ${e.message}`,
        e.status === 409 ? h("button", { type: "button", onclick: () => app.route() }, "Reload") : null);
    } finally { busy = false; }
  }

  const finalBox = item.status === "final" ? h("section", { className: "card" }, h("h3", {}, `Final · ${item.resolution}`),
    item.adjudicator ? h("p", {}, `adjudicated by ${item.adjudicator}`) : null,
    h("dl", {}, ...FIELDS.flatMap((f) => [h("dt", {}, FIELD_LABELS[f]), h("dd", {}, showValue(f, (item.final || {})[f]))]))) : null;
  // the history opens over the panel (its own scroll), from the button row
  const history = h("details", { className: "history", id: "history" }, h("summary", {}, "History"),
    h("div", { className: "history-pop" }, h("p", { className: "muted" }, "loading…")));
  history.addEventListener("toggle", async () => {
    if (!history.open || history.dataset.loaded) return;
    history.dataset.loaded = "1";
    const { events } = await api(`/api/items/${id}/history`);
    history.lastChild.replaceChildren(h("h3", {}, "History of this item"), h("ol", { className: "events" }, ...events.map((e) => h("li", {},
      h("span", { className: "muted" }, e.at.replace("T", " ").replace("+00:00", " UTC")), " ", h("b", {}, e.actor), " ",
      h("span", { className: "pill" }, e.kind), e.item_id !== id ? h("span", { className: "muted" }, ` (item ${e.item_id})`) : null,
      e.after && e.after.status ? ` → ${e.after.status}` : "", e.detail ? h("q", {}, e.detail) : null))));
  });
  const side = h("aside", { className: "side wide adjudication" },
    claimError ? h("div", { className: "banner error" }, claimError) : null,
    h("section", { className: "card" }, h("div", { className: "card-head" }, h("h3", {}, "Model and reviewers"), versionLine(p)), table),
    decidable ? h("section", { className: "card decision" },
      h("h3", {}, "Decide the disputed ", h("i", { className: "disputed-key", title: "the marked rows above" }),
        ` field${disputed.length > 1 ? "s" : ""}`),
      controls.el,
      rationale,
      h("div", { className: "decision-buttons" },
        h("button", { type: "button", className: "primary", id: "btn-adjudicate", onclick: submit }, "Make final ", h("kbd", {}, "S")),
        h("button", { type: "button", className: "ghost", onclick: () => app.go("#/queue") }, "Queue ", h("kbd", {}, "Q")),
        h("label", { className: "exclude" }, exclude, " Not a usable failure: exclude it"),
        history),
      status) : h("div", {}, finalBox, h("div", { className: "decision-buttons" }, history)));
  root.replaceChildren(episodeHeader(item), h("div", { className: "item-layout" }, h("div", { className: "stage" }, media.el), side));
  media.start();

  return {
    destroy: () => media.destroy(),
    onKey(e) {
      if (itemKeys(e, media, controls, p)) return true;
      const k = e.key.toLowerCase();
      if (k === "s") { submit(); return true; }
      return false;
    },
  };
}
