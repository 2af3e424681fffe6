// The page's colour scheme, in one place so that it stays consistent.
// Time markers (the model's, yours, other reviewers', the adjudicator's) are achromatic: told
// apart by line style and a label, never by hue. Simulator events take the one reserved red.
// Objects take chromatic colours from a categorical palette (Okabe-Ito, colour-blind safe)
// that contains neither grey nor that red, so a marker can never be read as an object line.
export const EVENT = "#dc2626";
export const PLAYHEAD = "#0f172a";

export const MARKERS = {
  you: { color: "#111827", dash: [], width: 2.5 },
  final: { color: "#111827", dash: [], width: 2.5 },
  model: { color: "#57534e", dash: [7, 4], width: 2 },
};
// reviewers on the adjudication page, in the order of their reviews
const REVIEWER_DASHES = [[2, 3], [9, 3, 2, 3], [12, 5], [1, 2]];
const REVIEWER_GREYS = ["#374151", "#4b5563", "#1f2937", "#6b7280"];
export function reviewerMarker(i) {
  return { color: REVIEWER_GREYS[i % REVIEWER_GREYS.length], dash: REVIEWER_DASHES[i % REVIEWER_DASHES.length], width: 2 };
}

export const OBJECT_PALETTE = ["#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9", "#a6761d", "#7570b3", "#b8a100"];

// evidence that is not an object: pale fills in their own rows, not lines
export const FILLS = { gripper: "#cbd5e1", contacts: "#94a3b8", goal: "#a7b4c6" };
export const PHASE_COLORS = { pre: "#eef2f6", during: "#fde7dd", post: "#e8ecf6" };

// a CSS background drawing a marker's line style (legend swatches and label edges)
export function dashCss(m) {
  if (!m.dash.length) return m.color;
  let at = 0;
  const stops = m.dash.map((len, i) => {
    const c = i % 2 ? "transparent" : m.color, stop = `${c} ${at}px ${at + len}px`;
    at += len;
    return stop;
  });
  return `repeating-linear-gradient(90deg, ${stops.join(", ")})`;
}
