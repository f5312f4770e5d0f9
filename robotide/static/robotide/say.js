// The "Say to the robot" box (templates/robots/_say.html), on the robot page and in the
// workbench's robot panel: the phrase goes on the robot's websocket (htmx's ws extension
// opened it on the box's [ws-connect] ancestor) as {"say": text}; the answer comes back on it
// as HTML (robots.say). Enter or Say sends; the box is then emptied for the next phrase. While
// the socket is not open, the robot page's box posts as a plain form.
(function () {
  "use strict";

  var sockets = new WeakMap(); // [ws-connect] element -> htmx's socket wrapper

  document.addEventListener("htmx:wsOpen", function (event) {
    sockets.set(event.target, event.detail.socketWrapper);
  });
  document.addEventListener("htmx:wsClose", function (event) {
    sockets.delete(event.target);
  });

  function send(box) {
    var input = box.querySelector("[data-say-text]");
    var holder = box.closest("[ws-connect]");
    var socket = holder && sockets.get(holder);
    if (!input || !socket) return false;
    var text = input.value.trim();
    if (text) socket.send(JSON.stringify({ say: text }));
    input.value = "";
    input.focus();
    return true;
  }

  document.addEventListener("submit", function (event) {
    var box = event.target.closest("form[data-say]");
    if (box && send(box)) event.preventDefault();
  });
  document.addEventListener("click", function (event) {
    var button = event.target.closest("div[data-say] [data-say-send]");
    if (button) send(button.closest("[data-say]"));
  });
  document.addEventListener("keydown", function (event) {
    if (event.key !== "Enter" || !event.target.matches("div[data-say] [data-say-text]")) return;
    event.preventDefault(); // not the editor's form around the panel
    send(event.target.closest("[data-say]"));
  });
})();
