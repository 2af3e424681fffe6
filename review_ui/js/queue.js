// The queue page: what I hold, what is open to me, what I decided; conflicts for adjudicators.
import { api } from "./api.js";
import { h } from "./dom.js";
import { progressCounts } from "./progress.js";

function table(rows, cols, empty) {
  if (!rows.length) return h("p", { className: "muted empty" }, empty);
  return h("table", { className: "list" },
    h("thead", {}, h("tr", {}, ...cols.map((c) => h("th", {}, c.title)))),
    h("tbody", {}, ...rows.map((r) => h("tr", { dataset: { item: String(r.id) } }, ...cols.map((c) => h("td", {}, c.cell(r)))))));
}

const episode = (r) => h("div", {}, h("div", {}, r.instruction),
  h("div", { className: "muted small" }, r.key, r.revision > 1 ? ` · rev ${r.revision}` : "",
    r.quarantined ? h("span", { className: "pill quarantine" }, "quarantined") : null));

export async function queuePage(root, app) {
  const q = await api("/api/queue");
  const link = (href, label, id) => h("a", { href, className: "button small", id }, label);
  const start = h("button", { type: "button", className: "primary big", id: "btn-start", onclick: () => app.next(),
    disabled: !q.held.length && !q.available_total }, q.held.length ? "Continue reviewing " : "Start reviewing ", h("kbd", {}, "N"));
  const sections = [
    h("section", { className: "card hero" },
      h("div", {}, h("h1", {}, `Hello ${q.user}`),
        h("p", { className: "muted" }, `${q.held.length} held by you · ${q.available_total} open to you · ${q.reviewed.length} decided by you`,
          q.conflicts.length ? ` · ${q.conflicts.length} conflicts to adjudicate` : ""),
        q.progress ? progressCounts(q.progress) : null),
      start),
  ];
  if (q.role !== "reviewer") {
    sections.push(h("section", { className: "card", id: "conflicts" }, h("h2", {}, "Conflicts to adjudicate"),
      table(q.conflicts, [
        { title: "episode", cell: episode },
        { title: "disputed", cell: (r) => r.disputed.map((d) => h("span", { className: "pill warn" }, d.replaceAll("_", " "))) },
        { title: "", cell: (r) => r.claimed_by_other ? h("span", { className: "muted" }, "being adjudicated")
          : link(`#/adjudicate/${r.id}`, "Adjudicate", `adjudicate-${r.id}`) },
      ], "No conflicts waiting.")));
  }
  sections.push(
    h("section", { className: "card", id: "held" }, h("h2", {}, "Held by you"),
      table(q.held, [{ title: "episode", cell: episode }, { title: "", cell: (r) => link(`#/item/${r.id}`, "Review", `review-${r.id}`) }],
        "Nothing held. Start reviewing to take the next item.")),
    h("section", { className: "card", id: "available" }, h("h2", {}, `Open to you (${q.available_total})`),
      table(q.available, [{ title: "episode", cell: episode }, { title: "", cell: (r) => link(`#/item/${r.id}`, "Review", `open-${r.id}`) }],
        "The queue is empty for you.")),
    h("section", { className: "card", id: "mine" }, h("h2", {}, "Your decisions"),
      table(q.reviewed, [
        { title: "episode", cell: episode },
        { title: "decision", cell: (r) => h("span", { className: `pill ${r.decision}` }, r.decision) },
        { title: "item", cell: (r) => r.state === "open" ? link(`#/item/${r.id}`, "Change", `change-${r.id}`) : h("span", { className: "muted" }, "closed") },
      ], "No decisions yet.")));
  root.replaceChildren(h("div", { className: "queue" }, ...sections));
  return { onKey: (e) => (e.key.toLowerCase() === "n" ? (app.next(), true) : false) };
}

export async function statusPage(root) {
  const s = await api("/api/status");
  const f = (x) => (x == null ? "—" : Number(x).toFixed(3));
  const ag = s.agreement;
  root.replaceChildren(h("div", { className: "queue" },
    h("section", { className: "card" }, h("h2", {}, `Queue · ${s.counts.total} items (${s.counts.quarantined} quarantined)`),
      h("div", { className: "counts" }, ...Object.entries(s.counts.by_status).map(([k, v]) => h("div", { className: "count" }, h("b", {}, v), k)))),
    h("section", { className: "card" }, h("h2", {}, `Reviewer agreement · ${ag.items} items with 2+ reviews`),
      h("table", { className: "list" }, h("thead", {}, h("tr", {}, ...["field", "kappa", "Krippendorff α", "agreement"].map((c) => h("th", {}, c)))),
        h("tbody", {},
          ...["recovery_level", "failure_category"].map((k) => h("tr", {}, h("td", {}, k), h("td", {}, `${f(ag[k].kappa)} (${ag[k].kappa_kind || "—"})`),
            h("td", {}, `${f(ag[k].alpha)} (${ag[k].alpha_metric})`), h("td", {}, f(ag[k].percent_agreement)))),
          h("tr", {}, h("td", {}, "fail_time_s"), h("td", {}, "—"), h("td", {}, `${f(ag.fail_time_s.alpha_interval)} (interval)`),
            h("td", {}, `${f(ag.fail_time_s.within_tau)} within ±${ag.fail_time_s.tau_s} s`)),
          h("tr", {}, h("td", {}, "recovery_action"), h("td", {}, "—"), h("td", {}, "—"), h("td", {}, f(ag.recovery_action.percent_agreement)))))),
    h("section", { className: "card" }, h("h2", {}, "Model vs final"),
      ...s.model_vs_final.by_characterizer.map((g) => h("p", {}, h("b", {}, g.version), ` · n=${g.n} · level accuracy ${f(g.level.accuracy)} · category accuracy ${f(g.category.accuracy)}`)),
      ...s.model_vs_final.by_localizer.map((g) => h("p", {}, h("b", {}, g.version), ` · n=${g.n} · failure-time MAE ${f(g.mean_abs_error_s)} s · within τ ${f(g.within_tau)}`)),
      h("p", { className: "muted" }, "Confusion matrices: run ", h("code", {}, "recover review status"), " (writes stage3/review_confusion.png)."))));
  return {};
}
