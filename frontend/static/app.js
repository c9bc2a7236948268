// Small page helpers; htmx does the rest.
//
// --- text from the server goes into pages as text ----------------------------------------------------------
// Names, units, selection texts, bit names, problem titles and details may come from an uploaded profile or another
// user: build elements and set textContent; where an HTML string is needed, every value goes through escape().
// The Content-Security-Policy (web/security_headers.py) allows no inline script besides.
window.drivebench = window.drivebench || {};
(() => {
  const drivebench = window.drivebench;
  // The sub-path the server is reached under behind a reverse proxy (<body data-root>, web/root.py; "" at the top):
  // url("/api/…") is the address a script fetches, appPath(location.pathname) the server's own path (a `next`).
  drivebench.root = document.body.dataset.root || "";
  drivebench.url = (path) => drivebench.root + path;
  drivebench.appPath = (path) => (drivebench.root && (path === drivebench.root || path.startsWith(`${drivebench.root}/`))
    ? path.slice(drivebench.root.length) || "/" : path);
  const ENTITIES = { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" };
  drivebench.escape = (text) => String(text ?? "").replace(/[&<>"']/g, (c) => ENTITIES[c]);

  // The scripts' texts in the page's language: they are marked _("…") (pybabel extracts them, babel.cfg), and the
  // server puts their translations into <script type="application/json" id="js-messages"> (base.html; none in
  // English). {name} in a text is replaced by values[name].
  let messages = null;
  drivebench.gettext = (text, values = {}) => {
    if (messages === null) {
      const tag = document.getElementById("js-messages");
      messages = tag ? JSON.parse(tag.textContent) : {};
    }
    return (messages[text] || text).replace(/\{(\w+)\}/g, (whole, name) => (name in values ? String(values[name]) : whole));
  };
  const _ = drivebench.gettext;

  // ``root`` (an element htmx loaded, or the body) if it matches ``selector``, and the elements in it that do
  drivebench.within = (root, selector) => {
    if (!root.querySelectorAll) return [];
    return [...(root.matches(selector) ? [root] : []), ...root.querySelectorAll(selector)];
  };

  // An element with attributes and children (strings become text nodes): el("li", {className: "x"}, "a", child)
  drivebench.el = (tag, props = {}, ...children) => {
    const node = Object.assign(document.createElement(tag), props);
    node.append(...children.filter((child) => child !== null && child !== undefined && child !== false));
    return node;
  };

  // The error box of the pages: <div class="error" role="alert"><strong>title</strong> detail</div>
  drivebench.errorBox = (title, detail) => {
    const box = drivebench.el("div", { className: "error" }, title ? drivebench.el("strong", {}, title) : null,
                              title && detail ? " " : "", detail || "");
    box.setAttribute("role", "alert");
    return box;
  };
  // An RFC 9457 problem (or no JSON body) as that box.
  drivebench.problemBox = (problem, status) => problem && (problem.title || problem.detail)
    ? drivebench.errorBox(problem.title || _("Error"), problem.detail)
    : drivebench.errorBox(_("Request failed"), `(HTTP ${status})`);

  // One JSON request of a page script: answers {status, data} (data null when the answer holds no JSON). ``headers``
  // are added; ``form``: the body is FormData, sent as it is. A request that gets no answer at all rejects.
  drivebench.requestJson = async (method, url, body, { headers = {}, form = false } = {}) => {
    const sent = { ...headers };
    if (!form && body !== undefined) sent["Content-Type"] = "application/json";
    const response = await fetch(url, { method, headers: sent,
                                        body: body === undefined ? undefined : (form ? body : JSON.stringify(body)) });
    let data = null;
    try { data = await response.json(); } catch (e) { data = null; }
    return { status: response.status, data };
  };

  // One websocket client for every live page: the URL on this server, JSON messages to onMessage, reconnects with
  // back-off (retryMs doubled up to maxRetryMs, back to retryMs once open) while keepOpen(closeEvent) holds.
  // path may be a function (a query that changes between connections). Returns {send(message), close(), open}.
  drivebench.liveSocket = (path, { onMessage, onOpen, onClose, keepOpen = () => true, retryMs = 1000,
                                   maxRetryMs = 10000 }) => {
    let socket = null;
    let timer = null;
    let delay = retryMs;
    let stopped = false;
    const url = () => `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}` +
      (typeof path === "function" ? path() : path);
    function connect() {
      timer = null;
      socket = new WebSocket(url());
      socket.onopen = (event) => { delay = retryMs; if (onOpen) onOpen(event); };
      socket.onmessage = (event) => {
        let message;
        try { message = JSON.parse(event.data); } catch (e) { console.warn("websocket: not JSON", e); return; }
        onMessage(message);
      };
      socket.onclose = (event) => {
        if (onClose) onClose(event);
        if (stopped || !keepOpen(event)) { stopped = true; return; }
        timer = setTimeout(connect, delay);
        delay = Math.min(delay * 2, maxRetryMs);
      };
    }
    connect();
    return {
      send(message) {
        if (!socket || socket.readyState !== WebSocket.OPEN) return false;
        socket.send(typeof message === "string" ? message : JSON.stringify(message));
        return true;
      },
      close() { stopped = true; clearTimeout(timer); if (socket) socket.close(); },
      get open() { return Boolean(socket) && socket.readyState === WebSocket.OPEN; },
      get stopped() { return stopped; },
    };
  };
})();

// --- errors next to the action --------------------------------------------------------------------------------
// Errors (problem fragments with a 4xx/5xx status) are shown next to the action that caused them: in the
// element named by the nearest data-error-target, else the nearest .action-result, else the toast slot.
// They never replace the content the request aimed at.
function errorSlot(elt) {
  const holder = elt.closest("[data-error-target]");
  if (holder) return document.querySelector(holder.dataset.errorTarget);
  const card = elt.closest(".card, form, tr");
  const local = card && (card.querySelector(".action-result") || card.closest(".card")?.querySelector(".action-result"));
  return local || document.getElementById("toast");
}

document.body.addEventListener("htmx:beforeSwap", (event) => {
  const xhr = event.detail.xhr;
  if (xhr.status < 400) return;
  if (xhr.status === 428 && event.detail.requestConfig.elt.closest("[data-asks-moving]")) {
    event.detail.shouldSwap = false;  // the page's dialog asks (below), naming the node and the values
    event.detail.isError = false;
    return;
  }
  const replacing = event.detail.requestConfig.elt.closest("[data-error-swap]");
  if (replacing) {  // the error response is a re-rendered form with the error inside it
    event.detail.shouldSwap = true;
    event.detail.isError = false;
    event.detail.swapOverride = replacing.dataset.errorSwap;
    return;
  }
  const slot = errorSlot(event.detail.requestConfig.elt);
  const isHtml = (xhr.getResponseHeader("Content-Type") || "").startsWith("text/html");
  let html = xhr.responseText;  // an error fragment the server rendered (escaped by Jinja)
  if (!isHtml) {
    let problem = null;
    try { problem = JSON.parse(xhr.responseText); } catch (e) { problem = null; }
    html = window.drivebench.problemBox(problem, xhr.status).outerHTML;
  }
  event.detail.shouldSwap = true;
  event.detail.isError = false;
  event.detail.target = slot;
  event.detail.swapOverride = "innerHTML";
  event.detail.serverResponse = html;
});

document.body.addEventListener("htmx:sendError", (event) => {
  errorSlot(event.detail.requestConfig.elt).replaceChildren(
    window.drivebench.errorBox(window.drivebench.gettext("No answer from the DriveBench server."),
                               window.drivebench.gettext("Is it still running?")));
});

// Behaviour that used to be inline handlers (the CSP runs none): a form that only htmx sends, a field whose text is
// selected by a click (a share link, a new token).
document.addEventListener("submit", (event) => {
  if (event.target.matches("form[data-no-submit]")) event.preventDefault();
});
document.addEventListener("click", (event) => {
  const field = event.target.closest && event.target.closest("[data-select-on-click]");
  if (field) field.select();
});

// The language links lead back to the page as it is now: a tab or set chosen since the page loaded (hx-push-url)
// is in the address, not in the link the server wrote.
document.addEventListener("click", (event) => {
  const link = event.target.closest && event.target.closest(".lang-switch a[href*='next=']");
  if (!link) return;
  const target = new URL(link.href);
  target.searchParams.set("next", window.drivebench.appPath(location.pathname) + location.search);
  link.href = target.pathname + target.search;
});

// Live fields (data-live on a filter or calculator htmx sends as the user types, "typed-early" among its triggers):
// what was typed or chosen while the page was still loading reached no listener, as htmx sets up its triggers only
// once the page's scripts have run (a slow network, a busy machine), and then takes the typed text as the unchanged
// start value. Sent as soon as they are set up: nothing the user typed is ignored.
function chosenEarly(select) {
  const options = [...select.options];
  const marked = options.filter((option) => option.defaultSelected);  // none marked: the first is shown
  return select.selectedIndex !== (marked.length ? options.indexOf(marked[marked.length - 1]) : 0);
}
function sendTypedEarly(live) {
  const fields = live.matches("input, select") ? [live] : [...live.querySelectorAll("input, select")];
  const changed = fields.some((field) => (field.tagName === "SELECT" ? chosenEarly(field)
    : field.value !== field.defaultValue));
  if (changed) htmx.trigger(live, "typed-early");
}
htmx.onLoad((root) => window.drivebench.within(root, "[data-live]").forEach(sendTypedEarly));

// A successful action clears an old error beside it.
document.body.addEventListener("htmx:afterRequest", (event) => {
  if (event.detail.successful && event.detail.xhr.status < 400) {  // not the error just shown there
    const slot = errorSlot(event.detail.elt);
    if (slot && slot.id !== "toast" && slot.querySelector(".error")) slot.innerHTML = "";
  }
});

// CSRF (web/access.py): with a signed-in session, every same-origin unsafe fetch carries the page's token, as
// htmx requests do through hx-headers on <body>.
(() => {
  const token = document.body.dataset.csrf;
  if (!token) return;
  const plainFetch = window.fetch.bind(window);
  window.fetch = (resource, options = {}) => {
    const method = (options.method || (resource instanceof Request ? resource.method : "GET")).toUpperCase();
    const url = new URL(resource instanceof Request ? resource.url : resource, location.href);
    if (["GET", "HEAD", "OPTIONS"].includes(method) || url.origin !== location.origin) return plainFetch(resource, options);
    const headers = new Headers(options.headers || (resource instanceof Request ? resource.headers : undefined));
    headers.set("X-CSRF-Token", token);
    return plainFetch(resource, { ...options, headers });
  };
})();

// --- safety interlocks: one client id per browser tab (X-DriveBench-Client) --------------------------------
// The node write lease and the keep-alive of what a tab started belong to this id (safety.js uses the same one).
window.drivebenchClientId = window.drivebenchClientId || (() => {
  let id = null;
  try { id = sessionStorage.getItem("drivebench.client"); } catch (e) { id = null; }
  if (!id) {
    id = Array.from(crypto.getRandomValues(new Uint8Array(8)), (b) => b.toString(16).padStart(2, "0")).join("");
    try { sessionStorage.setItem("drivebench.client", id); } catch (e) { /* private mode: one id per page load */ }
  }
  return id;
})();
document.addEventListener("htmx:configRequest", (event) => {
  event.detail.headers["X-DriveBench-Client"] = window.drivebenchClientId;
});

// Anything that can make a drive move is confirmed with what it will send: the server refuses the request with 428
// and names the node (confirm_node) and the values (confirm_values) it would send; the page's dialog lists them, and
// confirmed, the same request goes again carrying both. The server refuses it again (a new dialog) when the values
// it would send by then differ, so nothing is ever confirmed once for a page. Pages call drivebench.moving (fetch)
// or opt in with data-asks-moving (htmx forms and buttons); the page's keep-alive socket then holds the node.
(() => {
  const _ = window.drivebench.gettext;
  let dialog = null;
  // the shared dialog's words after the values; an action the keep-alive does not hold (a program download) passes
  // its own (ask's ``note``)
  const KEEP_ALIVE_NOTE = () => _("Once sent, this page keeps the node alive (every 0.5 s); when the page closes or " +
    "the network is lost, the server sends quick stop within 2 s.");
  // a broadcast the server marks with "reaches" (LSS, NMT to all, activate bit timing) moves no drive by itself: it
  // reaches every device on the bus, the unconfigured ones too, and the keep-alive holds none of them
  const EVERY_DEVICE_HEAD = () => _("Every device on this bus hears it");
  const EVERY_DEVICE_NOTE = () => _("It also reaches devices this session does not know. The server refuses it " +
    "while a drive of the session is enabled or armed.");

  function askDialog() {
    if (dialog) return dialog;
    dialog = document.createElement("dialog");
    dialog.id = "moving-confirm";
    const form = document.createElement("form");
    form.method = "dialog";
    const head = document.createElement("h3");
    head.className = "moving-confirm-head";
    const text = document.createElement("p");
    text.className = "moving-confirm-text";
    const values = document.createElement("ul");
    values.className = "moving-confirm-values";
    const note = document.createElement("p");
    note.className = "muted moving-confirm-note";
    const row = document.createElement("div");
    row.className = "ctl-row";
    for (const [value, label, cls] of [["cancel", _("Cancel"), "secondary"], ["ok", _("Send it"), "moving warn"]]) {
      const button = document.createElement("button");
      button.value = value;
      button.textContent = label;
      button.className = cls;
      row.append(button);
    }
    form.append(head, text, values, note, row);
    dialog.append(form);
    document.body.append(dialog);
    return dialog;
  }

  // "0x60FF Target velocity [rpm]": 2500 -> "0x60FF Target velocity: 2500 rpm" (the unit travels in the name)
  function valueLine(key, value) {
    const unit = key.match(/^(.*) \[([^\]]+)\]$/);
    const shown = typeof value === "boolean" ? (value ? _("yes") : _("no"))
      : Array.isArray(value) ? value.join(", ") : String(value);
    return unit ? `${unit[1]}: ${shown} ${unit[2]}` : `${key}: ${shown}`;
  }

  // Show the question of a 428 problem in ``host`` (the page's own dialog, else the shared one): what will be sent
  // to which node, each value with its unit (text only). Resolves true when confirmed. With ``hold`` the confirm
  // button is itself hold-to-run: pressing it calls hold.press(), releasing it hold.release(); the dialog stays
  // open for the next press until it is closed (resolves false then).
  function ask(problem, { host = null, what = "", okLabel = "", hold = null, note = "" } = {}) {
    const box = host || askDialog();
    const node = problem.confirm_node;
    const everyDevice = node === "all" && "reaches" in (problem.confirm_values || {});
    const head = box.querySelector(".moving-confirm-head");
    if (head) head.textContent = everyDevice ? EVERY_DEVICE_HEAD() : _("The drive may move");
    const aside = box.querySelector(".moving-confirm-note");
    if (aside) aside.textContent = note || (everyDevice ? EVERY_DEVICE_NOTE() : KEEP_ALIVE_NOTE());
    const text = box.querySelector(".moving-confirm-text");
    const whom = node === "all" ? _("every node of the session") : _("node {node}", { node });
    text.textContent = what ? _("{what}: sends to {whom}:", { what, whom }) : _("Sends to {whom}:", { whom });
    const list = box.querySelector(".moving-confirm-values");
    list.replaceChildren(...Object.entries(problem.confirm_values || {}).map(([key, value]) => {
      const li = document.createElement("li");
      li.className = "mono";
      li.textContent = valueLine(key, value);
      return li;
    }));
    const ok = box.querySelector("button[value=ok]");
    const label = ok.dataset.label || ok.textContent;
    ok.dataset.label = label;
    ok.textContent = okLabel || label;
    box.returnValue = "";
    return new Promise((resolve) => {
      const off = [];
      if (hold) {
        let held = false;
        const press = (event) => {
          event.preventDefault();
          held = true;
          ok.classList.add("held");
          // held means held: a line appearing on the page (internal limit, how a jog ended) must not move the
          // button from under the pointer and end the jog; the capture keeps the pointer on it until released
          try { ok.setPointerCapture(event.pointerId); } catch (e) { /* not a pointer event (keyboard) */ }
          hold.press();
        };
        const release = () => { if (!held) return; held = false; ok.classList.remove("held"); hold.release(); };
        const click = (event) => event.preventDefault();  // a click does not close it: holding runs, release stops
        ok.addEventListener("pointerdown", press);
        ok.addEventListener("click", click);
        for (const name of ["pointerup", "pointerleave", "pointercancel"]) ok.addEventListener(name, release);
        off.push(() => {
          release();
          ok.removeEventListener("pointerdown", press);
          ok.removeEventListener("click", click);
          for (const name of ["pointerup", "pointerleave", "pointercancel"]) ok.removeEventListener(name, release);
        });
      }
      if (!hold) {
        // a chained question (the mode, then the target) opens in the same dialog milliseconds after the previous
        // one closed, under the pointer: the second click of a double click confirms nothing; each question is
        // answered by a click of its own (a keyboard press has detail 0)
        const secondClick = (event) => { if (event.detail > 1) event.preventDefault(); };
        ok.addEventListener("click", secondClick);
        off.push(() => ok.removeEventListener("click", secondClick));
      }
      box.addEventListener("close", () => {
        off.forEach((undo) => undo());
        ok.textContent = label;
        resolve(!hold && box.returnValue === "ok");
      }, { once: true });
      box.showModal();
    });
  }

  // send(confirmation) makes the request (confirmation: null, or {confirm, confirm_values} to add) and answers
  // {status, data}; a 428 is asked (options as ask) and sent again confirmed, as often as the server asks anew.
  // Answers the last {status, data}, or null when the user cancelled.
  async function moving(send, options = {}) {
    let answer = await send(null);
    while (answer.status === 428 && answer.data && "confirm_node" in answer.data) {
      if (!await ask(answer.data, options)) return null;
      answer = await send({ confirm: answer.data.confirm_node, confirm_values: answer.data.confirm_values });
    }
    return answer;
  }
  window.drivebench.askMoving = ask;
  window.drivebench.moving = moving;

  // htmx: an element (or the form around it) with data-asks-moving that gets a 428 fragment asks; confirmed, the
  // same element sends again, with the node and values added to that one request only.
  const pending = new WeakMap();
  document.body.addEventListener("htmx:configRequest", (event) => {
    const confirmation = pending.get(event.detail.elt);
    if (!confirmation) return;
    pending.delete(event.detail.elt);
    event.detail.parameters.confirm = String(confirmation.confirm);
    event.detail.parameters.confirm_values = JSON.stringify(confirmation.confirm_values);
  });
  document.body.addEventListener("htmx:confirm", (event) => {
    if (!pending.has(event.detail.elt)) return;
    event.preventDefault();  // its own question (hx-confirm) was answered before the server asked
    event.detail.issueRequest(true);
  });
  // The answer is heard on the element itself: the websocket may re-render the node table between the click and
  // the 428, and htmx then fires htmx:afterRequest on a detached button whose event never reaches the body.
  document.body.addEventListener("htmx:beforeRequest", (event) => {
    const elt = event.detail.elt;
    if (!elt.closest || !elt.closest("[data-asks-moving]")) return;
    const answered = (done) => {
      if (done.target !== elt) return;  // a request of an element inside it
      elt.removeEventListener("htmx:afterRequest", answered);
      if (done.detail.xhr.status === 428) askAndResend(elt, done.detail.xhr.responseText);
    };
    elt.addEventListener("htmx:afterRequest", answered);
  });

  // A live table pushed over the websocket (the Plant page's node table, twice a second) is not redrawn while one of
  // its buttons is pressed: a redraw between press and release replaces the button, and the click lands on the table
  // (nothing sent, nothing said). The next push, after the release, redraws it.
  let pressed = null;
  document.addEventListener("pointerdown", (event) => { pressed = event.target; }, true);
  document.addEventListener("keydown", (event) => {
    if (event.key === " " || event.key === "Enter") pressed = event.target;
  }, true);
  for (const name of ["pointerup", "pointercancel", "keyup"]) {
    document.addEventListener(name, () => { setTimeout(() => { pressed = null; }, 0); }, true);  // after the click
  }
  document.body.addEventListener("htmx:oobBeforeSwap", (event) => {
    const target = event.detail.target;
    if (pressed && target && target.contains && target.contains(pressed)) event.detail.shouldSwap = false;
  });

  async function askAndResend(elt, responseText) {
    // the server's answer, read in an inert document (nothing in it runs or loads)
    const found = new DOMParser().parseFromString(responseText, "text/html").querySelector("[data-confirm-node]");
    if (!found) return;
    let values = {};
    try { values = JSON.parse(found.dataset.confirmValues || "{}"); } catch (e) { return; }
    const node = /^\d+$/.test(found.dataset.confirmNode) ? Number(found.dataset.confirmNode) : found.dataset.confirmNode;
    const problem = { confirm_node: node, confirm_values: values };
    if (!await ask(problem)) {  // cancelled: nothing was sent, and no red message of an earlier try stays beside it
      const slot = errorSlot(current(elt) || elt);
      if (slot && slot.id !== "toast") slot.querySelectorAll(".error").forEach((box) => box.remove());
      return;
    }
    const now = current(elt);  // the same control, as the page shows it now
    if (!now) {
      document.getElementById("toast").replaceChildren(window.drivebench.errorBox(
        _("Nothing was sent."), _("The page changed while you were asked: press the button again.")));
      return;
    }
    pending.set(now, { confirm: node, confirm_values: values });
    htmx.trigger(now, now.tagName === "FORM" ? "submit" : "click");
  }

  // the element, or the one with its id that a re-render put in its place
  function current(elt) {
    if (elt.isConnected) return elt;
    return elt.id ? document.getElementById(elt.id) : null;
  }
})();
// --- end safety interlocks ---------------------------------------------------------------------------------
