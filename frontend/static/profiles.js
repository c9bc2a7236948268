// Profiles page, one profile: a click (or Enter) on an entry row shows its details row below it.
document.addEventListener("click", (event) => toggleEntry(event.target.closest("tr.entry")));
document.addEventListener("keydown", (event) => {
  if (event.key === "Enter" && event.target.matches("tr.entry")) toggleEntry(event.target);
});
function toggleEntry(row) {
  const details = row && row.nextElementSibling;
  if (!details || !details.classList.contains("entry-detail")) return;
  details.hidden = !details.hidden;
  row.setAttribute("aria-expanded", String(!details.hidden));
}

// Many files at once: the upload's progress in the form's bar (htmx reports it per form; no inline handler under the
// Content-Security-Policy).
document.body.addEventListener("htmx:xhr:progress", (event) => {
  const form = event.target.closest && event.target.closest("form[data-upload-progress]");
  const bar = form && form.querySelector("progress");
  if (!bar) return;
  bar.hidden = false;
  if (event.detail.total) bar.value = (100 * event.detail.loaded) / event.detail.total;
});
