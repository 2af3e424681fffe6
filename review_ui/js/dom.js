// Tiny DOM helpers: h(tag, props, ...children), text escaping by construction (no innerHTML).
export function h(tag, props = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(props || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith("on") && typeof v === "function") el.addEventListener(k.slice(2), v);
    else if (k === "dataset") Object.assign(el.dataset, v);
    else if (k in el && typeof v !== "string") el[k] = v;
    else if (k === "className") el.className = v;
    else if (k in el && k !== "list" && k !== "form") el[k] = v;
    else el.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

export function fmtTime(t) { return t == null ? "—" : `${Number(t).toFixed(2)} s`; }

export const CATEGORY_KEYS = {
  grasp_failure: "G", placement_failure: "P", object_displacement: "D",
  collision_or_interaction_failure: "C", environmental_obstruction: "E", other: "O",
};
export const LEVEL_NAMES = { L1: "action retry", L2: "action adaptation", L3: "object state recovery", L4: "environmental recovery" };
export function categoryLabel(c) { return c ? c.replaceAll("_", " ").replace(" or ", " / ") : "—"; }
