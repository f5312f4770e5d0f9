// The "Say to the robot" box (templates/robots/_say.html): htmx's ws-send sends it on the
// robot's websocket; once sent it is emptied for the next phrase, the focus staying in it.
// Loaded by the box itself, so on the workbench once per panel: listen once.
if (!window.robotideSay) {
  window.robotideSay = true;
  document.addEventListener("htmx:wsAfterSend", function (event) {
    var form = event.target.closest ? event.target.closest("form[data-say]") : null;
    if (form) form.elements.say.value = "";
  });
}
