// Small page helpers; htmx does the rest.
//
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
  const replacing = event.detail.requestConfig.elt.closest("[data-error-swap]");
  if (replacing) {  // the error response is a re-rendered form with the error inside it
    event.detail.shouldSwap = true;
    event.detail.isError = false;
    event.detail.swapOverride = replacing.dataset.errorSwap;
    return;
  }
  const slot = errorSlot(event.detail.requestConfig.elt);
  const isHtml = (xhr.getResponseHeader("Content-Type") || "").startsWith("text/html");
  let html = xhr.responseText;
  if (!isHtml) {
    try {
      const problem = JSON.parse(xhr.responseText);
      html = `<div class="error" role="alert"><strong>${problem.title}</strong> ${problem.detail}</div>`;
    } catch (e) {
      html = `<div class="error" role="alert">Request failed (HTTP ${xhr.status})</div>`;
    }
  }
  event.detail.shouldSwap = true;
  event.detail.isError = false;
  event.detail.target = slot;
  event.detail.swapOverride = "innerHTML";
  event.detail.serverResponse = html;
});

document.body.addEventListener("htmx:sendError", (event) => {
  errorSlot(event.detail.requestConfig.elt).innerHTML =
    '<div class="error" role="alert"><strong>No answer from the DriveBench server.</strong> Is it still running?</div>';
});

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
// --- end safety interlocks ---------------------------------------------------------------------------------
