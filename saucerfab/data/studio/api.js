// The studio's HTTP API (saucerfab/studio/README.md) seen from the page.
//
// Every call either returns the parsed JSON body or throws an ApiError whose
// message is the server's own `error` text: the page shows that text as it
// is (it names the problem and the fix) and never a stack trace.

export class ApiError extends Error {
  constructor(message, status) {
    super(message);
    this.name = "ApiError";
    this.status = status;
  }
}

async function parse(response) {
  const text = await response.text();
  let body = null;
  if (text) {
    try {
      body = JSON.parse(text);
    } catch {
      body = null;
    }
  }
  if (response.status === 401) {
    // signed out (the cookie expired, the token changed, or sign-out in another tab): the page itself
    // answers with the sign-in form now
    window.location.reload();
  }
  if (!response.ok) {
    const message = body && typeof body.error === "string" ? body.error : `the server answered ${response.status} ${response.statusText}`;
    throw new ApiError(message, response.status);
  }
  return body;
}

export async function request(method, path, body) {
  const init = { method, headers: {} };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch {
    throw new ApiError("the studio server does not answer; is `saucerfab studio` still running?", 0);
  }
  return parse(response);
}

export const getJSON = (path) => request("GET", path);
export const postJSON = (path, body) => request("POST", path, body ?? {});

/** Upload one file's raw bytes (not multipart) under a role; returns the upload record. */
export async function upload(file, role) {
  const url = `/api/uploads?role=${encodeURIComponent(role)}&name=${encodeURIComponent(file.name)}`;
  let response;
  try {
    response = await fetch(url, { method: "POST", headers: { "Content-Type": "application/octet-stream" }, body: file });
  } catch {
    throw new ApiError("the upload did not reach the server; is `saucerfab studio` still running?", 0);
  }
  return parse(response);
}

/** URL of an upload fitted into its square frame, as the design will fit it. */
export function fittedUrl(uploadId, fit, background, size = 256) {
  const q = new URLSearchParams({ fit, size: String(size) });
  if (background) q.set("background", background);
  return `/api/uploads/${encodeURIComponent(uploadId)}/fitted.png?${q}`;
}

// "deleted" is what the event stream says when the run folder went away under it
export const FINAL = new Set(["done", "failed", "cancelled", "interrupted", "deleted"]);

/**
 * Follow one run: Server-Sent Events while they work, polling GET /api/runs/{id}
 * when the stream fails (a proxy that buffers, a dropped connection).
 * onProgress(progress) and onStatus(record) are called as things change;
 * returns a function that stops watching.
 */
export function watchRun(runId, { onProgress, onStatus, pollMs = 1500 }) {
  let stopped = false;
  let source = null;
  let timer = null;
  let lastProgress = "";

  const stop = () => {
    stopped = true;
    if (source) source.close();
    if (timer) clearTimeout(timer);
  };

  const poll = async () => {
    if (stopped) return;
    try {
      const record = await getJSON(`/api/runs/${runId}`);
      if (stopped) return;
      const progressText = JSON.stringify(record.progress ?? null);
      if (record.progress && progressText !== lastProgress) {
        lastProgress = progressText;
        onProgress(record.progress);
      }
      onStatus(record);
      if (FINAL.has(record.status)) return stop();
    } catch {
      // a passing network error: try again on the next tick
    }
    timer = setTimeout(poll, pollMs);
  };

  if (typeof EventSource === "undefined") {
    poll();
    return stop;
  }
  source = new EventSource(`/api/runs/${runId}/events`);
  source.addEventListener("progress", (ev) => {
    try {
      lastProgress = ev.data;
      onProgress(JSON.parse(ev.data));
    } catch {
      /* a malformed event is skipped; the next one replaces it */
    }
  });
  source.addEventListener("status", (ev) => {
    let record;
    try {
      record = JSON.parse(ev.data);
    } catch {
      return;
    }
    onStatus(record);
    // the server ends the stream after a final status; close first so the
    // browser does not try to reconnect
    if (FINAL.has(record.status)) stop();
  });
  source.onerror = () => {
    if (stopped) return;
    // the stream broke before a final status: poll instead
    source.close();
    source = null;
    poll();
  };
  return stop;
}
