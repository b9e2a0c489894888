// The main area's view of one design: status, live progress, the looks as
// they refine, the results (views, height change, verify, the 3D print) and
// its exports. Pure rendering from the server's records; studio.js decides
// which run is shown and wires the buttons.

import { getJSON, postJSON } from "./api.js";

const $ = (sel, root = document) => root.querySelector(sel);

const STATUS_TEXT = {
  queued: "queued",
  running: "running",
  cancelling: "cancelling…",
  cancelled: "cancelled",
  interrupted: "interrupted",
  failed: "failed",
  done: "done",
};
const VIEW_TEXT = {
  composite: "What the viewer sees",
  direct: "On the saucer",
  reflected: "In the cup",
  reflected2: "In the cup, second picture",
  height_change: "Height change",
};

export const runFileUrl = (runId, path) => `/api/runs/${encodeURIComponent(runId)}/files/${path.split("/").map(encodeURIComponent).join("/")}`;

export function statusBadge(node, status) {
  node.textContent = STATUS_TEXT[status] ?? status ?? "";
  node.className = `badge status-${status}`;
}

export function human(text) {
  return String(text ?? "").replace(/_/g, " ");
}

/** People's words for the optimizer's keys (GET /api/options' `labels`, saucerfab/labels.py); set once at start. */
const LABELS = { stages: {}, energies: {}, hidden_energies: [], stop_reasons: {} };
export function setLabels(labels) {
  Object.assign(LABELS, labels ?? {});
}
const stageText = (name) => LABELS.stages[name] ?? human(name);
const energyText = (key) => LABELS.energies[key] ?? human(String(key ?? "").replace(/^E_/, ""));
const stopText = (reason) => LABELS.stop_reasons[reason] ?? human(reason);

function seconds(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "";
  const whole = Math.round(s);
  if (whole < 60) return `${whole} s`;
  return `${Math.floor(whole / 60)} min ${String(whole % 60).padStart(2, "0")} s`;
}

function number(v) {
  if (typeof v !== "number" || !Number.isFinite(v)) return String(v ?? "");
  const a = Math.abs(v);
  if (a !== 0 && a < 1e-3) return v.toExponential(2);
  // four significant digits, grouped: an image error of 369,700 rather than 3.697e+5
  return Number(v.toPrecision(4)).toLocaleString("en", { maximumFractionDigits: 20 });
}

/** A captioned image; keeps the <img> (and so its pixels) when only the caption changes. */
function figure(gallery, key, url, caption) {
  let fig = gallery.querySelector(`figure[data-key="${key}"]`);
  if (!fig) {
    fig = document.createElement("figure");
    fig.dataset.key = key;
    fig.append(document.createElement("img"), document.createElement("figcaption"));
    gallery.append(fig);
  }
  const img = fig.querySelector("img");
  if (img.getAttribute("src") !== url) img.src = url;
  img.alt = caption;
  fig.querySelector("figcaption").textContent = caption;
  return fig;
}

export class RunView {
  constructor() {
    this.runId = null;
    this.viewerFor = null;
  }

  clear() {
    this.runId = null;
    this.viewerFor = null;
    $("#run").hidden = true;
    $("#looks-gallery").replaceChildren();
    $("#results-gallery").replaceChildren();
    $("#exports").replaceChildren();
    $("#viewer").removeAttribute("src");
  }

  /** Render a run record (GET /api/runs/{id} or an SSE status event). */
  show(record) {
    if (record.id !== this.runId) {
      this.clear();
      this.runId = record.id;
    }
    $("#run").hidden = false;
    $("#run-title").textContent = record.title || record.id;
    statusBadge($("#run-status"), record.status);
    $("#run-created").textContent = record.created ? `started ${new Date(record.created).toLocaleString()}` : "";
    const s = record.status;
    $("#run-cancel").hidden = !["queued", "running"].includes(s);
    $("#run-resume").hidden = !["cancelled", "interrupted", "failed"].includes(s);
    $("#run-delete").hidden = ["queued", "running", "cancelling"].includes(s);
    const err = $("#run-error");
    err.hidden = !record.error;
    err.textContent = record.error ?? "";
    // a cancelled or interrupted run's "error" says how to go on: a note, not an alarm
    err.className = `message ${s === "cancelled" || s === "interrupted" ? "note" : "error"}`;

    const active = s === "queued" || s === "running" || s === "cancelling";
    $("#progress").hidden = !active;
    this.status = s;
    if (s === "queued") {
      // a progress.json left by an earlier attempt says nothing about the wait
      // the run's place in the queue (the users take turns): record.queue, kept up to date by the event stream
      const q = record.queue;
      const wait = !q ? "it starts as soon as the designs before it are finished."
        : q.ahead === 0 ? "it starts next, as soon as a worker is free."
        : `${q.ahead} ${q.ahead === 1 ? "job" : "jobs"} ahead of you (place ${q.position} of ${q.queued}; the designers take turns).`;
      this.progressText(`Queued: ${wait}`, "");
      this.bar(0);
      $("#progress-energies").replaceChildren();
    } else if (record.progress) {
      this.progress(record.progress);
    }
    if (s === "done" && record.results) {
      this.results(record);
    } else {
      $("#results").hidden = true;
    }
    $("#export").hidden = s !== "done";
    if (s === "done") this.exports(record);
  }

  progressText(stage, time) {
    $("#progress-stage").textContent = stage;
    $("#progress-time").textContent = time;
  }

  /** Live progress: stage, iteration, energies, time left, and the latest looks. */
  bar(fraction) {
    const bar = $("#progress-bar");
    bar.setAttribute("aria-valuenow", String(Math.round(100 * fraction)));
    bar.firstElementChild.style.width = `${(100 * fraction).toFixed(1)}%`;
  }

  progress(p) {
    if (!this.runId || this.status === "queued") return;
    const stages = p.stages ?? 1;
    const index = p.stage_index ?? 0;
    const iters = p.max_iterations ? Math.min(1, (p.iteration ?? 0) / p.max_iterations) : 0;
    // stage_index counts from 0 while a stage runs; once a stage's look is in,
    // it counts that stage as done (the worker's progress.json)
    const stageDone = p.stage && p.looks?.stage === p.stage;
    let fraction = stageDone ? index / stages : (index + iters) / stages;
    let stage;
    if (p.phase === "verify") {
      stage = "Checking the design: a trial export, ray-traced (verify)";
      fraction = 1;
    } else if (!p.stage) {
      // the first look comes before the first stage reports: once it is shown, say what comes next
      stage = p.looks ? `First look ready; stage 1 of ${stages} is starting…` : "Reading the pictures and preparing the first look…";
    } else if (stageDone) {
      stage = `Stage ${Math.min(index, stages)} of ${stages} (${stageText(p.stage)}) finished`;
    } else {
      stage = `Stage ${Math.min(index + 1, stages)} of ${stages}: ${stageText(p.stage)}`;
      if (p.max_iterations) stage += `, iteration ${p.iteration ?? 0} of ${p.max_iterations}`;
    }
    fraction = Math.min(1, fraction);
    const time = [p.elapsed_s != null ? `${seconds(p.elapsed_s)} so far` : "", p.left_s != null ? `about ${seconds(p.left_s)} left` : ""]
      .filter(Boolean)
      .join(" · ");
    this.progressText(stage, time);
    this.bar(fraction);
    const dl = $("#progress-energies");
    dl.replaceChildren();
    for (const [k, v] of Object.entries(p.energies ?? {})) {
      if (LABELS.hidden_energies.includes(k)) continue; // a barrier's logarithms say nothing to a person
      const dt = document.createElement("dt");
      dt.textContent = energyText(k);
      const dd = document.createElement("dd");
      dd.textContent = number(v);
      dl.append(dt, dd);
    }
    if (p.looks && p.looks.files) this.looks(p.looks);
  }

  looks(looks) {
    const gallery = $("#looks-gallery");
    $("#looks").hidden = false;
    $("#looks-title").textContent = looks.stage === "first_look" ? "First look (the base shape, coloured from the pictures)" : `Preview after: ${stageText(looks.stage)}`;
    for (const view of ["composite", "direct", "reflected", "reflected2"]) {
      const path = looks.files[view];
      if (path) figure(gallery, view, runFileUrl(this.runId, path), VIEW_TEXT[view] ?? human(view));
    }
  }

  results(record) {
    const r = record.results;
    $("#results").hidden = false;
    $("#looks").hidden = true; // the results replace the previews
    const gallery = $("#results-gallery");
    for (const [view, url] of Object.entries(r.images ?? {})) {
      if (url) figure(gallery, view, url, VIEW_TEXT[view] ?? human(view));
    }
    metricsList($("#metrics"), r.metrics ?? {}, r.enhancement);
    stagesTable($("#stages"), r.metrics?.stages ?? []);
    if (r.viewer_url && this.viewerFor !== record.id) {
      this.viewerFor = record.id;
      const frame = $("#viewer");
      frame.src = r.viewer_url;
    }
    verifyTable($("#verify"), r.verify ?? [], { collapse: true });
    const link = $("#report-link");
    link.hidden = !r.report_url;
    if (r.report_url) link.href = r.report_url;
  }

  /** The run's exports (run.json's `exports`), each with its findings once finished. */
  async exports(record) {
    const box = $("#exports");
    for (const [printer, ex] of Object.entries(record.exports ?? {})) {
      let card = box.querySelector(`[data-printer="${printer}"]`);
      if (!card) {
        card = document.createElement("article");
        card.className = "export-card";
        card.dataset.printer = printer;
        box.append(card);
      }
      const litKey = litState(ex.lit);
      if (card.dataset.status === ex.status && FINAL_EXPORT.has(ex.status)) {
        // the export is as it was: only its view under the room light may have moved on
        if (ex.status === "done" && card.dataset.lit !== litKey) {
          card.dataset.lit = litKey;
          await this.lit(card, record.id, printer, ex.lit);
        }
        continue;
      }
      card.dataset.status = ex.status;
      card.dataset.lit = litKey;
      if (FINAL_EXPORT.has(ex.status)) {
        try {
          renderExport(card, printer, await getJSON(`/api/runs/${record.id}/exports/${encodeURIComponent(printer)}`));
        } catch (err) {
          renderExport(card, printer, { ...ex, error: err.message });
        }
      } else {
        renderExport(card, printer, ex);
      }
    }
  }

  /** The export card's part under the room light; a finished one's views come with the export's details. */
  async lit(card, runId, printer, lit) {
    const box = card.querySelector(".lit");
    if (!box) return;
    if (lit?.status === "done") {
      try {
        lit = (await getJSON(`/api/runs/${encodeURIComponent(runId)}/exports/${encodeURIComponent(printer)}`)).lit ?? lit;
      } catch (err) {
        lit = { ...lit, status: "failed", error: err.message };
      }
    }
    renderLit(box, printer, lit);
  }
}

/** What of an export's lit verify the card shows (its status, and its progress while it works). */
function litState(lit) {
  return lit ? `${lit.status}:${lit.progress?.fraction ?? ""}` : "";
}

const FINAL_EXPORT = new Set(["done", "failed"]);

/** Printer key -> its name (from /api/options), for the export cards' headings. */
const printerNames = new Map();
export function setPrinters(printers) {
  for (const p of printers ?? []) printerNames.set(p.key, p.name ?? p.key);
}
const PRINT_SUFFIX = /\.(3mf|obj|mtl|glb|gltf|ply|wrl|stl|zip)$/i;

/** Plain words for the design's summary numbers (results.metrics). */
const METRIC_TEXT = {
  E_visual_final: [() => `${energyText("E_visual")} at the end`, (v) => number(v)],
  max_abs_height_change: [() => "largest height change", (v) => number(v)],
  total_s: [() => "design time", (v) => seconds(v)],
};

function metricsList(dl, metrics, enhancement) {
  dl.replaceChildren();
  const add = (k, v) => dl.append(el("dt", "", k), el("dd", "", v));
  for (const [k, v] of Object.entries(metrics)) {
    if (typeof v !== "number" && typeof v !== "string") continue;
    const [label, fmt] = METRIC_TEXT[k] ?? [() => human(k), (x) => (typeof x === "number" ? number(x) : String(x))];
    add(label(), fmt(v));
  }
  const p = $("#enhancement-note");
  // results.enhancement: design.json's parameters.enhancement_used ({asked, strategy, why}) or a word
  const e = enhancement && typeof enhancement === "object" ? enhancement : enhancement ? { strategy: enhancement } : null;
  p.hidden = !e;
  if (e) p.textContent = `Conflict reduction: ${e.strategy === "subject" ? "black-white enhancement of each picture's subject" : human(e.strategy)}${e.why ? ` (${e.why})` : ""}.`;
}

/** The stages the optimiser ran (results.metrics.stages), one row each. */
function stagesTable(box, stages) {
  box.replaceChildren();
  if (!stages.length) return;
  const table = el("table", "verify stages");
  const head = el("tr");
  for (const h of ["stage", "iterations", energyText("E_visual"), energyText("E_deform"), "stopped"]) head.append(el("th", "", h));
  table.append(head);
  for (const st of stages) {
    const tr = el("tr");
    tr.append(
      el("td", "", stageText(st.name)),
      el("td", "num", st.iterations ?? ""),
      el("td", "num", st.E_visual != null ? number(st.E_visual) : ""),
      el("td", "num", st.E_deform != null ? number(st.E_deform) : ""),
      el("td", "", st.stop_reason ? stopText(st.stop_reason) : ""),
    );
    table.append(tr);
  }
  const details = el("details");
  details.append(el("summary", "", `Stages (${stages.length})`), table);
  box.append(details);
}

/** Start an export; returns its record (202). */
export function startExport(runId, printer, formats) {
  return postJSON(`/api/runs/${encodeURIComponent(runId)}/exports`, { printer, formats: formats.length ? formats : null });
}

/** Ask for an export seen under the room light; returns the export's record (202). */
export function startLit(runId, printer) {
  return postJSON(`/api/runs/${encodeURIComponent(runId)}/exports/${encodeURIComponent(printer)}/lit`);
}

function el(tag, className, text) {
  const e = document.createElement(tag);
  if (className) e.className = className;
  if (text !== undefined) e.textContent = text;
  return e;
}

function renderExport(card, printer, ex) {
  const head = el("div", "export-head");
  head.append(el("h4", "", printerNames.has(printer) ? `${printerNames.get(printer)} (${printer})` : printer));
  const badge = el("span");
  statusBadge(badge, ex.status);
  head.append(badge);
  if (ex.status === "done") {
    const ok = ex.printable !== false;
    head.append(el("span", ok ? "verdict ok" : "verdict bad", ok ? "printable" : "not printable"));
  }
  const parts = [head];
  if (ex.error) parts.push(el("p", "message error", ex.error));
  if (ex.status === "queued" || ex.status === "running") parts.push(el("p", "help", "Exporting, checking every file and ray-tracing the print…"));
  if (ex.status === "done") {
    // the print files and scene.json; the zip also holds the checks, verify pictures and report
    const all = ex.files ?? [];
    const files = all.filter((f) => !f.includes("/") && (PRINT_SUFFIX.test(f) || f === "scene.json"));
    if (files.length) parts.push(el("p", "files", `Print files: ${files.join(", ")}${all.length > files.length ? ` (and ${all.length - files.length} more in the zip: checks, verify pictures, report)` : ""}`));
    parts.push(findingsList(ex.check));
    if (ex.verify && ex.verify.length) {
      const v = el("div");
      verifyTable(v, ex.verify, { collapse: true });
      parts.push(el("h5", "", "The print, ray-traced from the viewer's eyes"), v);
    }
    const lit = el("div", "lit");
    renderLit(lit, printer, ex.lit);
    parts.push(lit);
    const links = el("p", "export-links");
    const zip = ex.zip_url ?? null;
    if (zip) {
      const a = el("a", "button primary", "Download the print files (.zip)");
      a.href = zip;
      a.setAttribute("download", "");
      a.dataset.download = printer;
      links.append(a);
    }
    if (ex.report_url) {
      const a = el("a", "", "Open the print's report");
      a.href = ex.report_url;
      a.target = "_blank";
      a.rel = "noopener";
      links.append(a);
    }
    parts.push(links);
  }
  card.replaceChildren(...parts);
}

const dB = (v) => (typeof v === "number" && Number.isFinite(v) ? v.toFixed(1) : "-");
const times = (a, b) => (typeof a === "number" && typeof b === "number" ? `${a.toFixed(2)}–${b.toFixed(2)}×` : "-");

/**
 * An export under the room light (the export record's `lit`, saucerfab/studio/lit.py): the button that asks
 * for it, its progress, or each view's picture under the light beside the emitted one, with the figures.
 */
function renderLit(box, printer, lit) {
  const parts = [el("h5", "", "Under a room light")];
  const status = lit?.status;
  if (!lit || status === "failed") {
    parts.push(el("p", "help", "Verify shows each colour as its own light in a perfect mirror. In a room the saucer is a "
      + "semi-glossy plastic lit by a lamp, the cup a polished metal, and the relief shades itself. Rendering that takes "
      + "about as long as the export's own verify."));
    if (lit?.error) parts.push(el("p", "message error", lit.error));
    const button = el("button", "", status === "failed" ? "Try again under the room light" : "See it under the room light");
    button.type = "button";
    button.dataset.lit = printer;
    parts.push(button);
  } else if (status === "queued" || status === "running") {
    const fraction = lit.progress?.fraction ?? 0;
    const line = el("div", "progress-line");
    line.append(el("span", "", status === "queued" ? "Waiting for a worker…" : `Rendering under the room light… ${Math.round(100 * fraction)} %`),
      el("span", "help", lit.progress?.message ?? ""));
    const bar = el("div", "bar");
    bar.setAttribute("role", "progressbar");
    bar.setAttribute("aria-label", "verify under the room light");
    bar.setAttribute("aria-valuenow", String(Math.round(100 * fraction)));
    const fill = el("div");
    fill.style.width = `${(100 * fraction).toFixed(1)}%`;
    bar.append(fill);
    parts.push(line, bar);
  } else if (status === "done") {
    const views = lit.views ?? [];
    parts.push(el("p", "help", `Path-traced at ${lit.res ?? "?"} px from the design eye: the saucer a semi-glossy plastic `
      + `under a dim room and a soft lamp above and in front, the cup ${lit.cup_metal ?? "metal"}. Each view is scored `
      + "against its picture under the light's smooth part, beside a flat print of it under the same light (the same plastic "
      + "without the relief: its gloss, the light itself); the shading pattern is the relief's own shading on a mid-grey "
      + "print (higher: weaker), beside a flat plate's under the same light."));
    const table = el("table", "verify lit-table");
    const head = el("tr");
    for (const h of ["view", "eye", "under the light (dB)", "a flat print (dB)", "emitted (dB)", "shading pattern (dB)", "flat plate (dB)", "shading range"]) head.append(el("th", "", h));
    table.append(head);
    for (const v of views) {
      const tr = el("tr");
      tr.append(el("td", "", human(v.view)), el("td", "", human(v.eye)), el("td", "num", dB(v.lit_psnr_db)),
        el("td", "num", dB(v.flat_print_lit_psnr_db)), el("td", "num", dB(v.emitted_psnr_db)), el("td", "num", dB(v.shading_pattern_db)), el("td", "num", dB(v.flat_pattern_db)),
        el("td", "num", `${times(v.shading_p5, v.shading_p95)} (flat ${times(v.flat_p5, v.flat_p95)})`));
      table.append(tr);
    }
    parts.push(table);
    for (const v of views) {
      // the emitted render (3 panels) and the lit one (4 panels) share one height: columns as wide as their panels
      const pair = el("div", "lit-pair");
      pair.dataset.view = `${v.view}-${v.eye}`;
      const name = `${human(v.view)} view, ${human(v.eye)} eye`;
      if (v.emitted_picture_url) figure(pair, "emitted", v.emitted_picture_url, `${name}: emitted colour, the cup a perfect mirror (${dB(v.emitted_psnr_db)} dB)`);
      if (v.lit_picture_url) figure(pair, "lit", v.lit_picture_url, `${name}: under the room light, the cup ${lit.cup_metal ?? "metal"} (${dB(v.lit_psnr_db)} dB; shading pattern ${dB(v.shading_pattern_db)} dB, a flat plate ${dB(v.flat_pattern_db)} dB)`);
      parts.push(pair);
    }
  }
  box.replaceChildren(...parts);
}

/** The checker's findings, per file; `check` is {file: {printable, findings}} or a list of such. */
function findingsList(check) {
  const box = el("div", "findings");
  if (!check) return box;
  const entries = Array.isArray(check) ? check.map((c) => [c.file ?? c.name ?? c.path ?? "", c]) : Object.entries(check);
  box.append(el("h5", "", "Printability"));
  const ul = el("ul");
  for (const [file, c] of entries) {
    const li = el("li", c.printable === false ? "bad" : "ok");
    li.append(el("strong", "", file), el("span", "", c.printable === false ? " not printable" : " printable"));
    // the check's counts, as the print's report says them ("0 errors, 0 warnings, 1 info finding")
    if (c.counts_text) li.append(el("span", "help", ` (${c.counts_text})`));
    const findings = (c.findings ?? []).filter((f) => f.severity !== "info" || (c.findings ?? []).length < 6);
    if (findings.length) {
      const inner = el("ul");
      for (const f of findings) inner.append(el("li", `sev-${f.severity}`, `${f.severity}: ${f.message}${f.code ? ` (${f.code})` : ""}`));
      li.append(inner);
    } else {
      li.append(el("span", "help", " — no findings"));
    }
    ul.append(li);
  }
  box.append(ul);
  return box;
}

/** verify rows [{view, eye, reference, psnr_db, coverage, passed, ...}] as a table, with any pictures the rows link. */
function verifyTable(box, rows, { collapse = false } = {}) {
  box.replaceChildren();
  if (!rows.length) {
    box.append(el("p", "help", "No verify results."));
    return;
  }
  const table = el("table", "verify");
  const head = el("tr");
  for (const h of ["view", "eye", "compared with", "PSNR (dB)", "coverage", ""]) head.append(el("th", "", h));
  table.append(head);
  const gallery = el("div", "gallery small");
  for (const row of rows) {
    const tr = el("tr");
    tr.append(
      el("td", "", human(row.view)),
      el("td", "", human(row.eye)),
      el("td", "", row.reference === "flat print" ? "a flat print, from this eye"
        : row.reference === "whole view" ? "each picture in its frame, its background around it" : "the picture"),
      el("td", "num", row.psnr_db != null ? Number(row.psnr_db).toFixed(1) : ""),
      // a whole view's stray shares (saucer, mirror) where a frame's coverage would stand
      el("td", "num", row.stray ? `stray ${row.stray.map((x) => (x != null ? `${Math.round(100 * x)} %` : "-")).join(" / ")}`
        : row.coverage != null ? `${Math.round(100 * row.coverage)} %` : ""),
      el("td", row.passed ? "ok" : "bad", row.passed ? "passed" : row.stray ? "stray" : "low"),
    );
    table.append(tr);
    for (const [k, v] of Object.entries(row)) {
      for (const [name, url] of pictureUrls(k, v)) {
        figure(gallery, `${row.view}-${row.eye}-${name}`, url, `${human(row.view)} view from the ${human(row.eye)} eye: ${human(name)}`);
      }
    }
  }
  box.append(table);
  if (gallery.childElementCount && collapse) {
    const details = el("details");
    details.append(el("summary", "", `Ray-traced pictures (${gallery.childElementCount}): the print, the picture it should show, their difference`), gallery);
    box.append(details);
  } else if (gallery.childElementCount) {
    box.append(gallery);
  }
}

/** [name, url] pairs of the picture links in a verify row field (a URL, or an object of URLs). */
function pictureUrls(key, value) {
  if (typeof value === "string" && /\.png(\?|$)/.test(value) && value.startsWith("/")) {
    const name = key.replace(/_url$/, "");
    return [[name === "picture" ? "ray-traced" : name, value]];
  }
  if (value && typeof value === "object" && !Array.isArray(value)) {
    return Object.entries(value).flatMap(([k, v]) => (typeof v === "string" && v.startsWith("/") && /\.png(\?|$)/.test(v) ? [[k, v]] : []));
  }
  return [];
}

