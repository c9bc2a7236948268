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
