// Blocks in the workbench: the Blockly workspace takes the textarea's place (the textarea keeps
// Blockly's JSON, which is what is saved, drafted and run), and beside it the Python the
// server makes of the blocks, read-only, refreshed as the blocks change.
(function () {
  "use strict";

  function cookie(name) { return window.robotideCookie(name); }

  document.addEventListener("DOMContentLoaded", function () {
    var bench = document.getElementById("blocks-bench");
    var textarea = document.getElementById("source");
    if (!bench || !textarea || !window.robotideBlocks) return;
    var pane = document.getElementById("blocks-python");
    var timer = null;

    function showPython() {
      timer = null;
      var data = new FormData();
      data.set("source", textarea.value);
      fetch(bench.dataset.pythonUrl, {
        method: "POST", body: data, credentials: "same-origin",
        headers: { "X-CSRFToken": cookie("csrftoken") },
      }).then(function (response) { return response.json(); }).then(function (answer) {
        pane.textContent = answer.python || answer.error || "";
        pane.classList.toggle("error", !answer.python);
      }, function () { /* offline: the next change tries again */ });
    }

    textarea.hidden = true;
    bench.hidden = false;
    window.robotideBlocksEditor = window.robotideBlocks.mount(
      document.getElementById("blocks-area"), textarea.value,
      function (json) {
        textarea.value = json;
        // The workbench's unsaved-changes and draft keeping listen for this.
        textarea.dispatchEvent(new Event("input", { bubbles: true }));
        if (timer) clearTimeout(timer);
        timer = setTimeout(showPython, 300);
      });
    showPython();
  });
})();
