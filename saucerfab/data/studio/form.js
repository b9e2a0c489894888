// The left column: pictures, masks, shape, cup, printer and the advanced
// options, turned into the options object of POST /api/runs.
//
// Files are uploaded the moment they are chosen (or dropped), so a bad file
// is refused at once with the server's message and a good one is shown
// fitted into its frame before any design starts.

import { fittedUrl, upload, postJSON } from "./api.js";

const $ = (sel, root = document) => root.querySelector(sel);

/** Picture roles shown with a fitted preview (the rest are plain file rows). */
const PICTURE_ROLES = ["direct", "reflected", "reflected2"];
const UPLOADED_SHAPE = "__upload__";

export class DesignForm {
  constructor(options, { onError, onPicturesChanged }) {
    this.options = options;
    this.onError = onError;
    this.onPicturesChanged = onPicturesChanged;
    this.uploads = {}; // role -> {id, name}
    this.duplicateOf = null; // the run whose options were loaded, for "duplicate with changes"
    this.el = $("#design-form");
    this.fill();
    this.wire();
    this.reset();
  }

  // ---- the controls' choices, from GET /api/options -------------------------------

  fill() {
    const o = this.options;
    setChoices($("#fit"), (o.fits ?? ["pad", "crop"]).map((f) => [f, f === "pad" ? "Pad: whole picture" : "Crop: fill the frame"]));
    const shapes = (o.shapes ?? []).map((s) => [s, s.replace(/_/g, " ")]);
    shapes.push([UPLOADED_SHAPE, "My heightfield (upload)…"]);
    setChoices($("#shape"), shapes);
    setChoices($("#scene"), sceneList(o.scenes).map((sc) => [sc.key, sc.label]));
    setChoices($("#cup-kind"), cupList(o.cups).map((c) => [c.kind, c.kind]));
    setChoices($("#printer"), (o.printers ?? []).map((p) => [p.key, p.name ? `${p.name} (${p.key})` : p.key]));
    setChoices($("#frames"), (o.frames ?? ["inscribed"]).map((f) => [f, f]));
    setChoices($("#enhancement"), (o.enhancements ?? ["auto"]).map((e) => [e, e]));
    const caps = o.stage_caps ?? {};
    const methodNames = { auto: "Automatic (the small-blur stage for photos only)", fast: "Fast: always two stages", paper: "The paper's three stages, as written" };
    setChoices($("#method"), (o.methods ?? ["auto"]).map((m) => [m, methodNames[m] ?? m]));
    // each method's cap: [pictures with a subject, photographs]
    $("#max-iters").placeholder = Object.entries(caps).map(([m, [a, b]]) => `${a === b ? a : `${a}/${b}`} (${m})`).join(", ");
    const samples = o.samples ?? [];
    $("#load-samples").hidden = !(samples.some((s) => s.role === "direct") && samples.some((s) => s.role === "reflected"));
  }

  /** The defaults of a new design. */
  reset() {
    const d = this.options.defaults ?? {};
    this.uploads = {};
    this.duplicateOf = null;
    for (const zone of this.el.querySelectorAll("[data-role]")) this.showFile(zone.dataset.role, null);
    for (const input of this.el.querySelectorAll('input[type="file"]')) input.value = "";
    $("#fit").value = d.fit ?? "pad";
    $("#background-auto").checked = true;
    $("#background").disabled = true;
    $("#scene").value = d.scene ?? sceneList(this.options.scenes)[0].key;
    $("#saucer-diameter").value = "";
    $("#shape").value = d.shape ?? "waves";
    $("#cup-kind").value = cupList(this.options.cups)[0]?.kind ?? "circle";
    $("#cup-params").value = "";
    $("#printer").value = d.printer ?? "j55";
    $("#cup-diameter").value = d.cup_diameter_mm ?? 80;
    $("#resolution").value = d.resolution ?? "";
    $("#image-size").value = d.image_size ?? "";
    $("#max-iters").value = d.max_iters ?? "";
    $("#seed").value = 0;
    $("#frames").value = d.frames ?? "inscribed";
    $("#enhancement").value = d.enhancement ?? "auto";
    $("#method").value = d.method ?? "auto";
    $("#verify-after").checked = d.verify ?? true;
    $("#title").value = "";
    this.syncDependent();
    this.showDuplicateNote();
  }

  wire() {
    for (const input of this.el.querySelectorAll('input[type="file"]')) {
      const role = input.closest("[data-role]").dataset.role;
      input.addEventListener("change", () => {
        if (input.files && input.files[0]) this.uploadFile(role, input.files[0]);
      });
    }
    // drag and drop onto a picture's frame
    for (const zone of this.el.querySelectorAll(".dropzone")) {
      const role = zone.dataset.role;
      zone.addEventListener("dragover", (ev) => {
        ev.preventDefault();
        zone.classList.add("over");
      });
      zone.addEventListener("dragleave", () => zone.classList.remove("over"));
      zone.addEventListener("drop", (ev) => {
        ev.preventDefault();
        zone.classList.remove("over");
        const file = ev.dataTransfer?.files?.[0];
        if (file) this.uploadFile(role, file);
      });
      // the frame opens the file picker too
      $(".frame", zone).addEventListener("click", () => $('input[type="file"]', zone).click());
    }
    $("#fit").addEventListener("change", () => this.refreshPreviews());
    $("#background").addEventListener("input", () => this.refreshPreviews());
    $("#background-auto").addEventListener("change", () => {
      $("#background").disabled = $("#background-auto").checked;
      this.refreshPreviews();
    });
    $("#shape").addEventListener("change", () => this.syncDependent());
    $("#cup-kind").addEventListener("change", () => this.syncDependent());
    $("#scene").addEventListener("change", () => this.syncDependent());
    $("#cup-diameter").addEventListener("input", () => this.syncDependent());
    $("#load-samples").addEventListener("click", () => this.loadSamples());
    $("#duplicate-clear").addEventListener("click", () => this.reset());
  }

  /** Show what depends on other choices: the shape upload, the prism's second picture, help texts. */
  syncDependent() {
    const rule = (this.options.fit_rules ?? {})[$("#fit").value];
    $("#fit-rule").textContent = rule ?? "";
    $("#shape-upload").hidden = $("#shape").value !== UPLOADED_SHAPE;
    const cup = cupList(this.options.cups).find((c) => c.kind === $("#cup-kind").value);
    $("#cup-usage").textContent = cup?.usage
      ? `Numbers as in ${cup.usage} (model units, degrees); empty for the defaults.`
      : "";
    // a round saucer's diameter: asked for a round scene only; empty, the scene's (a multiple of the cup's)
    const scene = this.scene();
    $("#saucer-diameter-box").hidden = !scene?.round;
    const cupMm = Number($("#cup-diameter").value);
    $("#saucer-diameter").placeholder = scene?.round && scene.saucer_per_cup && cupMm > 0
      ? `${+(scene.saucer_per_cup * cupMm).toFixed(1)} (${+scene.saucer_per_cup.toFixed(2)} × the cup)`
      : "the scene's";
    const prism = $("#cup-kind").value === "prism";
    $("#zone-reflected2").hidden = !prism;
    $("#mask-reflected2").hidden = !prism;
    this.el.querySelector(".pictures").classList.toggle("three", prism);
  }

  /** The chosen scene's entry of /api/options (key, label, round, saucer_per_cup). */
  scene() {
    return sceneList(this.options.scenes).find((sc) => sc.key === $("#scene").value);
  }

  // ---- uploads and previews --------------------------------------------------------

  async uploadFile(role, file) {
    this.onError(null);
    const zone = this.el.querySelector(`[data-role="${role}"]`);
    // refuse an oversized file here rather than stream it to a server that will refuse it too
    const limit = this.options.limits?.max_upload_bytes;
    if (limit && file.size > limit) {
      $(`input[type="file"]`, zone).value = "";
      this.onError(`${file.name} is ${(file.size / 2 ** 20).toFixed(1)} MiB; the studio takes uploads up to ${(limit / 2 ** 20).toFixed(0)} MiB. Downscale or re-compress it (a view frame is a few hundred pixels).`);
      return;
    }
    zone.classList.add("busy");
    $(".file-name", zone).textContent = `uploading ${file.name}…`;
    try {
      const record = await upload(file, role);
      this.uploads[role] = { id: record.id, name: record.name ?? file.name };
      this.showFile(role, this.uploads[role]);
    } catch (err) {
      delete this.uploads[role];
      this.showFile(role, null);
      $(`input[type="file"]`, zone).value = "";
      // the server's message usually names the file already
      this.onError(err.message.includes(file.name) ? err.message : `${file.name}: ${err.message}`);
    } finally {
      zone.classList.remove("busy");
      this.onPicturesChanged();
    }
  }

  async loadSamples() {
    this.onError(null);
    const samples = this.options.samples ?? [];
    try {
      for (const role of ["direct", "reflected"]) {
        const sample = samples.find((s) => s.role === role);
        const record = await postJSON(`/api/samples/${encodeURIComponent(sample.name)}`);
        this.uploads[role] = { id: record.id, name: record.name ?? sample.name };
        this.showFile(role, this.uploads[role]);
      }
    } catch (err) {
      this.onError(err.message);
    }
    this.onPicturesChanged();
  }

  fitRule() {
    return $("#fit").value;
  }

  background() {
    return $("#background-auto").checked ? null : $("#background").value;
  }

  previewUrl(role, size = 256) {
    const up = this.uploads[role];
    return up ? fittedUrl(up.id, this.fitRule(), this.background(), size) : null;
  }

  showFile(role, up) {
    const zone = this.el.querySelector(`[data-role="${role}"]`);
    if (!zone) return;
    $(".file-name", zone).textContent = up ? up.name : "";
    zone.classList.toggle("filled", Boolean(up));
    const img = $(".frame img", zone);
    if (img) {
      img.hidden = !up;
      if (up) {
        img.src = this.previewUrl(role);
        img.alt = `${up.name}, fitted into its frame`;
      } else {
        img.removeAttribute("src");
      }
    }
  }

  refreshPreviews() {
    this.syncDependent();
    for (const role of PICTURE_ROLES) if (this.uploads[role]) this.showFile(role, this.uploads[role]);
    this.onPicturesChanged();
  }

  /** The chosen pictures, for the larger previews of the main area. */
  pictures() {
    return PICTURE_ROLES.filter((r) => this.uploads[r] && !this.el.querySelector(`[data-role="${r}"]`).hidden).map((r) => ({
      role: r,
      name: this.uploads[r].name,
      url: this.previewUrl(r, 384),
    }));
  }

  // ---- options out and in ------------------------------------------------------------

  /** The options object of POST /api/runs; throws an Error naming what is missing. */
  collect() {
    const missing = ["direct", "reflected"].filter((r) => !this.uploads[r]);
    if (missing.length) {
      throw new Error(`choose ${missing.map((r) => (r === "direct" ? "the saucer's picture" : "the cup's picture")).join(" and ")} first`);
    }
    const prism = $("#cup-kind").value === "prism";
    const opts = {
      direct: this.uploads.direct.id,
      reflected: this.uploads.reflected.id,
      fit: this.fitRule(),
      background: this.background(),
      printer: $("#printer").value,
      frames: $("#frames").value,
      enhancement: $("#enhancement").value,
      method: $("#method").value,
      verify: $("#verify-after").checked,
    };
    const title = $("#title").value.trim();
    if (title) opts.title = title;
    for (const role of ["direct_mask", "reflected_mask"]) if (this.uploads[role]) opts[role] = this.uploads[role].id;
    if (prism) {
      if (this.uploads.reflected2) opts.reflected2 = this.uploads.reflected2.id;
      if (this.uploads.reflected2_mask) opts.reflected2_mask = this.uploads.reflected2_mask.id;
    }
    if ($("#shape").value === UPLOADED_SHAPE) {
      if (!this.uploads.shape) throw new Error("upload the base shape's heightfield (.npy or .png), or pick a built-in shape");
      opts.shape = this.uploads.shape.id;
    } else {
      opts.shape = $("#shape").value;
    }
    // the default cup (a circle with the scene's radius) is "no cup option"
    const kind = $("#cup-kind").value;
    const nums = $("#cup-params").value.trim().replace(/\s+/g, "");
    const firstKind = cupList(this.options.cups)[0]?.kind;
    opts.cup = kind === firstKind && !nums ? null : nums ? `${kind}:${nums}` : kind;
    // the default scene is "no scene option" (a run's options as before there was a choice)
    const scenes = sceneList(this.options.scenes);
    const defaultScene = this.options.defaults?.scene ?? scenes[0].key;
    opts.scene = $("#scene").value === defaultScene ? null : $("#scene").value;
    const numbers = { cup_diameter_mm: "#cup-diameter", resolution: "#resolution", image_size: "#image-size", max_iters: "#max-iters", seed: "#seed" };
    for (const [key, sel] of Object.entries(numbers)) {
      const text = $(sel).value.trim();
      if (text === "") continue;
      const n = Number(text);
      if (!Number.isFinite(n)) throw new Error(`${$(`label[for="${sel.slice(1)}"]`).textContent} must be a number`);
      opts[key] = n;
    }
    const saucer = $("#saucer-diameter").value.trim();
    if (this.scene()?.round && saucer !== "") {
      const n = Number(saucer);
      if (!Number.isFinite(n)) throw new Error("Saucer diameter (mm) must be a number");
      opts.saucer_diameter_mm = n;
    }
    return opts;
  }

  /** Load a run's options into the form ("duplicate with changes"). */
  load(run) {
    this.reset();
    const o = run.options ?? {};
    for (const role of ["direct", "reflected", "reflected2", "direct_mask", "reflected_mask", "reflected2_mask"]) {
      if (o[role]) this.uploads[role] = { id: o[role], name: `from “${run.title ?? run.id}”` };
    }
    const set = (sel, v) => {
      if (v !== undefined && v !== null) $(sel).value = v;
    };
    const fit = typeof o.fit === "string" && (this.options.fits ?? ["pad", "crop"]).includes(o.fit) ? o.fit : null;
    set("#fit", fit);
    if (o.background) {
      $("#background-auto").checked = false;
      $("#background").disabled = false;
      $("#background").value = o.background;
    }
    if (o.shape && (this.options.shapes ?? []).includes(o.shape)) {
      $("#shape").value = o.shape;
    } else if (o.shape) {
      $("#shape").value = UPLOADED_SHAPE;
      this.uploads.shape = { id: o.shape, name: `from “${run.title ?? run.id}”` };
    }
    if (o.cup) {
      const [kind, nums = ""] = String(o.cup).split(":");
      $("#cup-kind").value = kind;
      $("#cup-params").value = nums;
    }
    if (sceneList(this.options.scenes).some((sc) => sc.key === o.scene)) $("#scene").value = o.scene;
    set("#saucer-diameter", o.saucer_diameter_mm);
    set("#printer", o.printer);
    set("#cup-diameter", o.cup_diameter_mm);
    set("#resolution", o.resolution);
    set("#image-size", o.image_size);
    set("#max-iters", o.max_iters);
    set("#seed", o.seed);
    set("#frames", o.frames);
    set("#enhancement", o.enhancement);
    set("#method", o.method);
    if (typeof o.verify === "boolean") $("#verify-after").checked = o.verify;
    this.syncDependent();
    for (const role of Object.keys(this.uploads)) this.showFile(role, this.uploads[role]);
    this.duplicateOf = run;
    this.showDuplicateNote();
    this.onPicturesChanged();
    if (["resolution", "image_size", "max_iters", "seed", "frames", "enhancement", "method"].some((k) => k in o)) $("#advanced").open = true;
  }

  /** What differs from the run being duplicated (null where an option was dropped). */
  changesFrom(run, opts) {
    const before = run.options ?? {};
    const changes = {};
    for (const key of new Set([...Object.keys(before), ...Object.keys(opts)])) {
      const a = before[key] ?? null;
      const b = opts[key] ?? null;
      if (JSON.stringify(a) !== JSON.stringify(b)) changes[key] = b;
    }
    return changes;
  }

  showDuplicateNote() {
    const run = this.duplicateOf;
    $("#duplicate-note").hidden = !run;
    $("#duplicate-text").textContent = run ? `Options of “${run.title ?? run.id}” loaded: change what you like and start.` : "";
    $("#start").textContent = run ? "Start the changed copy" : "Start design";
  }
}

/** `cups` from /api/options as a list of {kind, usage}, whatever its exact form. */
function cupList(cups) {
  if (!cups) return [{ kind: "circle", usage: "" }];
  if (Array.isArray(cups)) return cups.map((c) => (typeof c === "string" ? { kind: c, usage: "" } : { kind: c.kind ?? c.name, usage: c.usage ?? c.spec_usage ?? "" }));
  return Object.entries(cups).map(([kind, usage]) => ({ kind, usage: typeof usage === "string" ? usage : usage?.usage ?? "" }));
}

/** `scenes` from /api/options as a list of {key, label, round, saucer_per_cup}; the paper's alone without it. */
function sceneList(scenes) {
  if (!Array.isArray(scenes) || !scenes.length) return [{ key: "paper", label: "Rectangle in front of the cup", round: false }];
  return scenes.map((sc) => (typeof sc === "string" ? { key: sc, label: sc, round: false } : sc));
}

function setChoices(select, pairs) {
  select.replaceChildren(
    ...pairs.map(([value, text]) => {
      const option = document.createElement("option");
      option.value = value;
      option.textContent = text;
      return option;
    }),
  );
}
