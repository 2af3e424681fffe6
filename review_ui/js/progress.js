// A reviewer's own progress (GET /api/progress): decisions today, items left to them, and
// how often their values agreed with the other reviewers' on items that have closed.
import { h } from "./dom.js";

const pct = (x) => `${Math.round(x * 100)} %`;
const SHORT = { fail_time_s: "time", recovery_level: "level", failure_category: "category", recovery_action: "action" };

export function agreementText(a) {
  if (!a || !a.closed_items) return "agreement: once your items close";
  return `agreement ${pct(a.all_fields)} over ${a.closed_items} closed item${a.closed_items > 1 ? "s" : ""}`;
}

// the one-line version for the top bar
export function progressLine(el, p) {
  el.replaceChildren(h("b", {}, String(p.done_today)), " done today · ", h("b", {}, String(p.left)), " left · ",
    agreementText(p.agreement));
  el.title = p.agreement && p.agreement.closed_items
    ? `agreement with the other reviewers, per field: ${Object.entries(p.agreement.by_field)
      .map(([f, x]) => `${f.replaceAll("_", " ")} ${x == null ? "—" : pct(x)}`).join(", ")} (${p.agreement.pairs} pairs)`
    : "your agreement with the other reviewers shows once items you reviewed have closed";
}

// the counts on the queue page
export function progressCounts(p) {
  const a = p.agreement || {};
  const count = (n, label, id) => h("div", { className: "count", id }, h("b", {}, String(n)), label);
  return h("div", { className: "counts", id: "my-progress" },
    count(p.done_today, "done today", "progress-today"),
    count(p.left, "left in the queue", "progress-left"),
    count(a.closed_items ? pct(a.all_fields) : "—", a.closed_items ? `agreement (${a.closed_items} closed)` : "agreement (none closed yet)", "progress-agreement"),
    a.closed_items ? h("div", { className: "count per-field", id: "progress-by-field" }, h("span", { className: "muted" }, "per field"),
      ...Object.entries(a.by_field).map(([f, x]) => h("span", {}, `${SHORT[f] || f} `, h("b", {}, x == null ? "—" : pct(x))))) : null);
}
