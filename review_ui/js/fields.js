// The four reviewed fields as controls: level and category buttons (with their keys), the
// failure time (with "set at playhead"), the recovery action. Shared by review and adjudication.
import { CATEGORY_KEYS, LEVEL_NAMES, categoryLabel, fmtTime, h } from "./dom.js";

export const FIELDS = ["fail_time_s", "recovery_level", "failure_category", "recovery_action"];
export const FIELD_LABELS = {
  fail_time_s: "Failure time", recovery_level: "Recovery level",
  failure_category: "Failure category", recovery_action: "Recovery action",
};

// the control step of a time, as the server snaps it (half-way goes to the later step)
export const snapStep = (t, hz) => Math.floor(t * hz + 0.5 + 1e-9);
export const gridTime = (t, hz) => Math.round(snapStep(t, hz) / hz * 1e6) / 1e6;

// equal as the server compares them: times on the same control step, actions up to spaces
export function same(field, a, b, hz = 20) {
  if (a == null || b == null) return a == b;
  if (field === "fail_time_s") return snapStep(Number(a), hz) === snapStep(Number(b), hz);
  if (field === "recovery_action") return a.trim().replace(/\s+/g, " ") === b.trim().replace(/\s+/g, " ");
  return a === b;
}

export function showValue(field, v) {
  if (v == null) return "—";
  if (field === "fail_time_s") return fmtTime(v);
  if (field === "failure_category") return categoryLabel(v);
  if (field === "recovery_level") return `${v} · ${LEVEL_NAMES[v] || ""}`;
  return v;
}

// Controls for a set of fields. `suggested` marks the model's value on each control.
export class FieldControls {
  constructor({ fields = FIELDS, values, suggested = {}, choices, onChange, getPlayhead, duration, controlHz = 20 }) {
    this.fields = fields;
    this.hz = controlHz;
    this.values = { ...values };
    this.suggested = suggested;
    this.onChange = onChange || (() => {});
    this.getPlayhead = getPlayhead;
    this.rows = {};
    this.el = h("div", { className: "fields" });
    for (const f of fields) {
      const err = h("p", { className: "field-error", id: `err-${f}`, hidden: true });
      const row = h("div", { className: "field", id: `field-${f}`, dataset: { field: f } },
        h("div", { className: "field-head" }, h("span", { className: "field-label" }, FIELD_LABELS[f]),
          h("span", { className: "edited-badge" }, "edited")),
        this._control(f, choices, duration), err);
      this.rows[f] = { row, err };
      this.el.append(row);
    }
    this.refresh();
  }

  _control(f, choices, duration) {
    if (f === "recovery_level") {
      return h("div", { className: "choice-grid levels" }, ...choices.recovery_level.map((lv, i) =>
        h("button", { type: "button", className: "choice", dataset: { value: lv }, id: `level-${lv}`,
          title: `${lv} · ${LEVEL_NAMES[lv] || ""}`, onclick: () => this.set(f, lv) },
        h("span", { className: "choice-text" }, h("b", {}, lv), " ", LEVEL_NAMES[lv] || ""), h("kbd", {}, String(i + 1)))));
    }
    if (f === "failure_category") {
      return h("div", { className: "choice-grid categories" }, ...choices.failure_category.map((c) =>
        h("button", { type: "button", className: "choice", dataset: { value: c }, id: `cat-${c}`,
          title: categoryLabel(c), onclick: () => this.set(f, c) },
        h("span", { className: "choice-text" }, categoryLabel(c)), h("kbd", {}, CATEGORY_KEYS[c] || ""))));
    }
    if (f === "fail_time_s") {
      this.timeInput = h("input", { type: "number", step: "0.05", min: "0", max: duration != null ? String(duration) : undefined,
        id: "input-fail-time", inputMode: "decimal", oninput: () => this.set(f, this.timeInput.value === "" ? null : Number(this.timeInput.value), false),
        // a typed time shows, once left, the control step it will be stored as
        onchange: () => {
          if (this.timeInput.value === "") return;
          const v = gridTime(Number(this.timeInput.value), this.hz);
          this.timeInput.value = String(v);
          this.set(f, v, false);
        } });
      return h("div", { className: "time-row" }, this.timeInput, h("span", { className: "unit" }, "s"),
        h("button", { type: "button", id: "btn-set-time", onclick: () => this.setTimeAtPlayhead() },
          "Set at playhead ", h("kbd", {}, "T")));
    }
    this.actionInput = h("textarea", { id: "input-action", rows: 2, maxLength: 400, placeholder: "a concise imperative",
      oninput: () => this.set(f, this.actionInput.value, false) });
    return this.actionInput;
  }

  setTimeAtPlayhead() {
    if (this.fields.includes("fail_time_s")) this.set("fail_time_s", this.getPlayhead());
  }

  set(f, v, sync = true) {
    if (!this.fields.includes(f)) return;
    this.values[f] = v;
    this.clearError(f);
    if (sync) this.refresh(); else this.refreshBadges();
    this.onChange(this.values);
  }

  refresh() {
    for (const f of this.fields) {
      const { row } = this.rows[f];
      row.querySelectorAll(".choice").forEach((b) => {
        b.classList.toggle("active", b.dataset.value === this.values[f]);
        b.classList.toggle("suggested", b.dataset.value === this.suggested[f]);
      });
    }
    if (this.timeInput && document.activeElement !== this.timeInput)
      this.timeInput.value = this.values.fail_time_s == null ? "" : String(this.values.fail_time_s);
    if (this.actionInput && document.activeElement !== this.actionInput) this.actionInput.value = this.values.recovery_action || "";
    this.refreshBadges();
  }

  // "edited" once a value is chosen and differs from the model's: an empty field (nothing
  // chosen yet, e.g. on the adjudication page) is not an edit
  refreshBadges() {
    for (const f of this.fields) {
      const v = this.values[f];
      this.rows[f].row.classList.toggle("edited", v != null && v !== "" && !same(f, v, this.suggested[f], this.hz));
    }
  }

  edits() {
    const out = {};
    for (const f of this.fields) if (!same(f, this.values[f], this.suggested[f], this.hz) && this.values[f] != null && this.values[f] !== "") out[f] = this.values[f];
    return out;
  }

  showError(field, message) {
    const r = this.rows[field];
    if (!r) return false;
    r.row.classList.add("invalid");
    r.err.textContent = message;
    r.err.hidden = false;
    r.row.scrollIntoView({ block: "nearest" });
    return true;
  }
  clearError(field) {
    const r = this.rows[field];
    if (!r) return;
    r.row.classList.remove("invalid");
    r.err.hidden = true;
  }
  disable(on) { this.el.querySelectorAll("button, input, textarea").forEach((n) => { n.disabled = on; }); }
}
