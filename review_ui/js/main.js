// Router, sign-in and the global keyboard for the review page.
// Routes: #/login  #/queue  #/item/<id>  #/adjudicate/<id>  #/status
import { adjudicatePage } from "./adjudicate.js";
import { api, ApiError, setCsrf } from "./api.js";
import { h } from "./dom.js";
import { progressLine } from "./progress.js";
import { queuePage, statusPage } from "./queue.js";
import { reviewPage } from "./review.js";

const view = document.getElementById("view");
let current = null;
let me = null;

const app = {
  go(hash) { if (location.hash === hash) app.route(); else location.hash = hash; },
  toast(text) {
    const t = document.getElementById("toast");
    t.textContent = text;
    t.classList.add("show");
    clearTimeout(app._toast);
    app._toast = setTimeout(() => t.classList.remove("show"), 2200);
  },
  async next() {
    try {
      const r = await api("/api/queue/next", { method: "POST" });
      if (r.item == null) { app.toast("Nothing left for you to review."); app.go("#/queue"); }
      else app.go(`#/item/${r.item}`);
    } catch (e) { failure(e); }
  },
  async route() {
    if (current && current.destroy) current.destroy();
    current = null;
    const [, page, id] = (location.hash || "#/queue").split("/");
    if (!me && page !== "login") { if (!(await whoami())) return app.go("#/login"); }
    view.dataset.page = page;
    document.body.dataset.page = page;
    if (me && page !== "login") refreshProgress();
    view.replaceChildren(h("p", { className: "muted loading" }, "Loading…"));
    try {
      if (page === "login") current = loginPage();
      else if (page === "item") current = await reviewPage(view, Number(id), app);
      else if (page === "adjudicate") current = await adjudicatePage(view, Number(id), app);
      else if (page === "status") current = await statusPage(view);
      else current = await queuePage(view, app);
    } catch (e) { failure(e); }
  },
};

function failure(e) {
  if (e instanceof ApiError && e.status === 401) { me = null; return app.go("#/login"); }
  view.replaceChildren(h("div", { className: "banner error" }, e instanceof ApiError ? `${e.status}: ${e.message}` : String(e),
    " ", h("a", { href: "#/queue" }, "back to the queue")));
  if (!(e instanceof ApiError)) console.error(e);
}

// the reviewer's own progress in the top bar, fetched on every page change (after decisions)
async function refreshProgress() {
  const el = document.getElementById("progress");
  try { progressLine(el, await api("/api/progress")); el.hidden = false; }
  catch (e) { el.hidden = true; if (!(e instanceof ApiError)) console.error(e); }
}

async function whoami() {
  try { me = await api("/api/me"); } catch (e) { if (e instanceof ApiError && e.status === 401) { me = null; return false; } throw e; }
  setCsrf(me.csrf);
  document.getElementById("nav").hidden = false;
  document.getElementById("whoami").textContent = `${me.user} · ${me.role}`;
  document.getElementById("nav-status").hidden = me.role === "reviewer";
  return true;
}

function loginPage() {
  const node = document.getElementById("tpl-login").content.cloneNode(true);
  view.replaceChildren(node);
  document.getElementById("nav").hidden = true;
  const form = document.getElementById("login-form");
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const err = document.getElementById("login-error");
    try {
      const r = await api("/api/login", { method: "POST", body: { token: form.token.value.trim() } });
      setCsrf(r.csrf);
      await whoami();
      app.go("#/queue");
    } catch (e) {
      err.hidden = false;
      err.textContent = e instanceof ApiError && e.status === 401 ? "That token is not valid." : `Sign-in failed: ${e.message}`;
    }
  });
  document.getElementById("token").focus();
  return {};
}

document.addEventListener("keydown", (e) => {
  const typing = e.target.closest && e.target.closest("input, textarea, select");
  if (typing) { if (e.key === "Escape") e.target.blur(); return; }
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (e.key === "?") { document.getElementById("help").showModal(); e.preventDefault(); return; }
  if (current && current.onKey && current.onKey(e)) { e.preventDefault(); return; }
  if (e.key.toLowerCase() === "q" && me) app.go("#/queue");
});

// a clicked button keeps no focus, so Space and letters stay with the page's keys
document.addEventListener("click", (e) => { const b = e.target.closest && e.target.closest("button, select"); if (b && e.detail) b.blur(); });
document.addEventListener("change", (e) => { if (e.target.id === "speed") e.target.blur(); });
document.getElementById("help-btn").addEventListener("click", () => document.getElementById("help").showModal());
document.getElementById("logout").addEventListener("click", async () => {
  try { await api("/api/logout", { method: "POST" }); } catch { /* signed out anyway */ }
  me = null; setCsrf(null);
  app.go("#/login");
});
window.addEventListener("hashchange", () => app.route());
app.route();
