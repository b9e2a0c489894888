// The workspace's designs (GET /api/runs, newest first: the signed-in user's, or everyone's for the
// admin) as a list of cards with thumbnails and status; a card opens its design in the main area.

import { statusBadge } from "./run.js";

const $ = (sel, root = document) => root.querySelector(sel);

/** `me`: the signed-in user; another user's design (the admin sees them all) is marked with its owner. */
export function renderHistory(runs, selectedId, onOpen, me) {
  const list = $("#history");
  $("#history-empty").hidden = runs.length > 0;
  const keep = new Map([...list.children].map((li) => [li.dataset.id, li]));
  const items = runs.map((run) => {
    let li = keep.get(run.id);
    if (!li) {
      li = document.createElement("li");
      li.dataset.id = run.id;
      const button = document.createElement("button");
      button.type = "button";
      button.className = "history-item";
      const thumb = document.createElement("div");
      thumb.className = "thumb";
      const text = document.createElement("div");
      text.className = "history-text";
      const title = document.createElement("span");
      title.className = "history-title";
      const meta = document.createElement("span");
      meta.className = "history-meta";
      const badge = document.createElement("span");
      const when = document.createElement("span");
      when.className = "when";
      const owner = document.createElement("span");
      owner.className = "history-owner";
      meta.append(badge, when, owner);
      text.append(title, meta);
      button.append(thumb, text);
      button.addEventListener("click", () => onOpen(li.dataset.id));
      li.append(button);
    }
    const button = li.firstElementChild;
    const by = run.owner && me && run.owner !== me ? `, ${run.owner}'s` : "";
    button.setAttribute("aria-label", `Open design ${run.title || run.id} (${run.status}${by})`);
    button.classList.toggle("selected", run.id === selectedId);
    li.querySelector(".history-title").textContent = run.title || run.id;
    statusBadge(li.querySelector(".history-meta span"), run.status);
    li.querySelector(".when").textContent = run.created ? new Date(run.created).toLocaleString([], { dateStyle: "short", timeStyle: "short" }) : "";
    const other = run.owner && me && run.owner !== me;
    li.querySelector(".history-owner").textContent = other ? ` · ${run.owner}` : "";
    li.title = run.error ?? "";
    const thumb = li.querySelector(".thumb");
    if (run.thumb_url) {
      let img = thumb.querySelector("img");
      if (!img) {
        img = document.createElement("img");
        img.alt = "";
        thumb.replaceChildren(img);
      }
      if (img.getAttribute("src") !== run.thumb_url) img.src = run.thumb_url;
    } else if (!thumb.querySelector(".placeholder")) {
      const ph = document.createElement("span");
      ph.className = "placeholder";
      thumb.replaceChildren(ph);
    }
    return li;
  });
  list.replaceChildren(...items);
}
