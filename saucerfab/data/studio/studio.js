// saucerfab studio: the page's entry point.
//
// State lives on the server (every design is a run folder in the workspace);
// the page keeps only which run is shown and what the form holds, so a
// reload, a second tab or a restarted server all show the same truth.
// Modules: api.js (HTTP, SSE with a polling fallback), form.js (the left
// column), run.js (one design's progress, results, exports), history.js.

import { getJSON, postJSON, request, watchRun, FINAL } from "./api.js";
import { DesignForm } from "./form.js";
import { RunView, setLabels, setPrinters, startExport, startLit } from "./run.js";
import { renderHistory } from "./history.js";

const $ = (sel, root = document) => root.querySelector(sel);

const state = {
  options: null,
  session: null, // who is signed in: {auth, user, admin} (GET /api/session)
  form: null,
  view: new RunView(),
  selected: null, // the id of the run shown in the main area
  record: null, // its latest record
  unwatch: null, // stops following it
  historyTimer: null,
  exportTimer: null,
};

// ---- messages ------------------------------------------------------------------------

/** Show the server's message (or ours) above the form; null hides it. */
function formError(message) {
  const box = $("#form-error");
  box.hidden = !message;
  box.textContent = message ?? "";
  if (message) box.scrollIntoView({ block: "nearest", behavior: "smooth" });
}

function runError(message) {
  const box = $("#run-error");
  box.hidden = !message;
  box.textContent = message ?? "";
}

// ---- the pictures in the main area before a design is chosen --------------------------

function showWelcome() {
  const pictures = state.form.pictures();
  const pair = $("#fitted-pair");
  pair.replaceChildren(
    ...pictures.map((p) => {
      const fig = document.createElement("figure");
      const img = document.createElement("img");
      img.src = p.url;
      img.alt = `${p.name}, fitted into its frame`;
      const cap = document.createElement("figcaption");
      cap.textContent = `${p.role === "direct" ? "On the saucer" : p.role === "reflected" ? "In the cup" : "In the cup, second picture"}: ${p.name}`;
      fig.append(img, cap);
      return fig;
    }),
  );
  $("#steps").hidden = pictures.length > 0;
  $("#welcome-text").textContent = pictures.length
    ? "Your pictures as the design will fit them into their square frames. Change the framing or the background on the left; then start the design."
    : "Choose a picture for the saucer and one for the cup on the left, then start the design. Each is shown here as the design will fit it into its square frame.";
}

// ---- one run: open, follow, act ------------------------------------------------------

async function openRun(runId) {
  if (state.unwatch) state.unwatch();
  state.unwatch = null;
  state.selected = runId;
  // keep the shown run in the address, so a reload or a bookmark comes back to it
  if (location.hash !== `#run=${runId}`) history.replaceState(null, "", `#run=${runId}`);
  runError(null);
  $("#welcome").hidden = true;
  try {
    const record = await getJSON(`/api/runs/${encodeURIComponent(runId)}`);
    if (state.selected !== runId) return;
    showRecord(record);
    if (!FINAL.has(record.status)) follow(runId);
  } catch (err) {
    state.view.clear();
    $("#welcome").hidden = false;
    formError(err.message);
  }
  refreshHistory();
}

/** Show no design: the welcome view with the chosen pictures. */
function closeRun() {
  if (state.unwatch) state.unwatch();
  state.unwatch = null;
  state.selected = null;
  state.record = null;
  clearTimeout(state.exportTimer);
  state.view.clear();
  $("#welcome").hidden = false;
  history.replaceState(null, "", location.pathname);
  renderHistory(lastRuns, null, openRun, state.session?.user);
}

function showRecord(record) {
  state.record = record;
  state.view.show(record);
  watchExports(record);
}

/** Follow a queued or running design: progress and looks as they come, then its results. */
function follow(runId) {
  state.unwatch = watchRun(runId, {
    onProgress: (p) => {
      if (state.selected === runId) state.view.progress(p);
    },
    onStatus: async (record) => {
      if (state.selected !== runId) return;
      // an SSE status event carries the record; results come with GET /api/runs/{id}
      if (record.status === "done" && !record.results) {
        try {
          record = await getJSON(`/api/runs/${encodeURIComponent(runId)}`);
        } catch (err) {
          runError(err.message);
        }
      }
      if (state.selected === runId) showRecord(record);
      refreshHistory();
    },
  });
}

/** While an export of the shown run is queued or running, re-read the run until it settles. */
function watchExports(record) {
  clearTimeout(state.exportTimer);
  const active = (s) => s === "queued" || s === "running";
  // an export at work, or one being rendered under the room light
  const busy = Object.values(record.exports ?? {}).some((e) => active(e.status) || active(e.lit?.status));
  if (!busy) return;
  state.exportTimer = setTimeout(async () => {
    if (state.selected !== record.id) return;
    try {
      showRecord(await getJSON(`/api/runs/${encodeURIComponent(record.id)}`));
    } catch (err) {
      runError(err.message);
    }
  }, 1500);
}

async function act(method, suffix, body) {
  const id = state.selected;
  if (!id) return null;
  runError(null);
  try {
    return await request(method, `/api/runs/${encodeURIComponent(id)}${suffix}`, body);
  } catch (err) {
    runError(err.message);
    return null;
  }
}

function wireRunButtons() {
  $("#run-cancel").addEventListener("click", async () => {
    const record = await act("POST", "/cancel");
    if (record) {
      showRecord(record);
      refreshHistory();
    }
  });
  $("#run-resume").addEventListener("click", async () => {
    const record = await act("POST", "/resume");
    if (record) openRun(record.id ?? state.selected);
  });
  $("#run-duplicate").addEventListener("click", () => {
    if (!state.record) return;
    state.form.load(state.record);
    formError(null);
    $("#design-form").scrollIntoView({ behavior: "smooth", block: "start" });
  });
  $("#new-design").addEventListener("click", () => {
    // back to an empty form and the welcome view; the designs stay in the history
    closeRun();
    state.form.reset();
    formError(null);
    showWelcome();
    window.scrollTo({ top: 0, behavior: "smooth" });
  });
  $("#run-delete").addEventListener("click", async () => {
    const title = state.record?.title ?? state.selected;
    if (!window.confirm(`Delete the design “${title}” and its print files?`)) return;
    const ok = await act("DELETE", "");
    if (ok === null && !$("#run-error").hidden) return;
    closeRun();
    showWelcome();
    refreshHistory();
  });
  $("#export-start").addEventListener("click", async () => {
    const formats = [...document.querySelectorAll('#export-formats input:checked')].map((i) => i.value);
    const printer = $("#export-printer").value;
    runError(null);
    try {
      await startExport(state.selected, printer, formats);
      showRecord(await getJSON(`/api/runs/${encodeURIComponent(state.selected)}`));
    } catch (err) {
      runError(err.message);
    }
  });
  // an export card's "See it under the room light" (the cards are drawn anew, so one listener on their box)
  $("#exports").addEventListener("click", async (ev) => {
    const button = ev.target.closest("button[data-lit]");
    if (!button) return;
    button.disabled = true;
    runError(null);
    try {
      await startLit(state.selected, button.dataset.lit);
      showRecord(await getJSON(`/api/runs/${encodeURIComponent(state.selected)}`));
    } catch (err) {
      runError(err.message);
      button.disabled = false;
    }
  });
}

// ---- starting a design -----------------------------------------------------------------

async function startDesign(ev) {
  ev.preventDefault();
  formError(null);
  let opts;
  try {
    opts = state.form.collect();
  } catch (err) {
    formError(err.message);
    return;
  }
  const button = $("#start");
  button.disabled = true;
  try {
    const source = state.form.duplicateOf;
    const record = source
      ? await postJSON(`/api/runs/${encodeURIComponent(source.id)}/duplicate`, state.form.changesFrom(source, opts))
      : await postJSON("/api/runs", opts);
    state.form.duplicateOf = null;
    state.form.showDuplicateNote();
    await openRun(record.id);
    // in the one-column layout (narrow windows) the design's view is below the form
    if (window.matchMedia("(max-width: 980px)").matches) $("#run").scrollIntoView({ behavior: "smooth", block: "start" });
  } catch (err) {
    formError(err.message);
  } finally {
    button.disabled = false;
  }
}

// ---- history ---------------------------------------------------------------------------

let lastRuns = [];

async function refreshHistory() {
  clearTimeout(state.historyTimer);
  let runs = lastRuns;
  try {
    runs = lastRuns = await getJSON("/api/runs");
    $("#server-state").textContent = "";
  } catch (err) {
    $("#server-state").textContent = err.message;
  }
  renderHistory(runs, state.selected, openRun, state.session?.user);
  // queued designs start without the page doing anything: look again while any wait or run
  const busy = runs.some((r) => !FINAL.has(r.status));
  state.historyTimer = setTimeout(refreshHistory, busy ? 2000 : 10000);
}

// ---- start -----------------------------------------------------------------------------

function fillExportControls(options) {
  const select = $("#export-printer");
  select.replaceChildren(
    ...(options.printers ?? []).map((p) => {
      const o = document.createElement("option");
      o.value = p.key;
      o.textContent = p.name ? `${p.name} (${p.key})` : p.key;
      return o;
    }),
  );
  select.value = options.defaults?.printer ?? "j55";
  const formats = options.formats ?? ["3mf", "obj", "glb", "ply", "wrl", "stl"];
  $("#export-formats").replaceChildren(
    ...formats.map((f) => {
      const label = document.createElement("label");
      label.className = "inline";
      const input = document.createElement("input");
      input.type = "checkbox";
      input.value = f;
      input.name = "format";
      label.append(input, ` ${f.toUpperCase()}`);
      return label;
    }),
  );
}

/** Who is signed in, and the sign-out button (none without sign-in). */
function showSession(session) {
  state.session = session;
  $("#sign-out").hidden = !session.auth;
  $("#who").textContent = session.user ?? "";
  $("#h-history").textContent = session.auth && !session.admin ? "Your designs" : "Designs in this workspace";
}

async function main() {
  try {
    const [options, session] = await Promise.all([getJSON("/api/options"), getJSON("/api/session")]);
    state.options = options;
    showSession(session);
  } catch (err) {
    $("#server-state").textContent = `The studio server did not answer: ${err.message}`;
    return;
  }
  state.form = new DesignForm(state.options, { onError: formError, onPicturesChanged: showWelcome });
  fillExportControls(state.options);
  setPrinters(state.options.printers);
  setLabels(state.options.labels);
  $("#design-form").addEventListener("submit", startDesign);
  wireRunButtons();
  showWelcome();
  // a reload keeps the design it showed (#run=ID)
  const m = /run=([\w-]+)/.exec(location.hash);
  await refreshHistory();
  if (m) openRun(m[1]);
  window.addEventListener("hashchange", () => {
    const h = /run=([\w-]+)/.exec(location.hash);
    if (h && h[1] !== state.selected) openRun(h[1]);
  });
  document.body.dataset.ready = "true";
}

main();
