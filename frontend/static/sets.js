// Parameter sets page: mark the set shown on the right in the list (htmx does the rest).
document.body.addEventListener("htmx:afterSettle", () => {
  const match = location.search.match(/[?&]set=(\d+)/);
  document.querySelectorAll(".set-row").forEach((row) => {
    row.classList.toggle("selected", Boolean(match) && row.dataset.set === match[1]);
  });
});
