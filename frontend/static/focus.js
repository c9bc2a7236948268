// Keyboard focus survives live updates: htmx swaps (a websocket pushing a table twice a second, a DIP switch
// re-rendering its calculator) replace the focused control with a fresh copy. The copy has the same id, so the
// focus moves to it. Focus the user moved away on purpose (a click elsewhere, Esc) is not brought back.
(() => {
  let focusedId = null;
  document.addEventListener("focusin", (event) => { focusedId = event.target.id || null; });
  document.addEventListener("focusout", (event) => {
    // a control removed by a swap loses focus without the user; one still in the page lost it by the user's hand
    if (!event.relatedTarget) {
      queueMicrotask(() => { if (event.target.isConnected) focusedId = null; });
    }
  });
  const restore = () => {
    if (!focusedId || (document.activeElement && document.activeElement !== document.body)) return;
    const again = document.getElementById(focusedId);
    if (again) again.focus({ preventScroll: true });
  };
  for (const name of ["htmx:afterSwap", "htmx:oobAfterSwap", "htmx:afterSettle", "htmx:wsAfterMessage"]) {
    document.body.addEventListener(name, restore);
  }
})();
