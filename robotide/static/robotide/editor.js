// The code editor: CodeMirror over the plain textarea (which is what a browser without
// scripts gets, and what the form submits either way).
(function () {
  "use strict";
  document.addEventListener("DOMContentLoaded", function () {
    var textarea = document.getElementById("source");
    // A blocks program is edited as blocks (blocks_bench.js); its text is Blockly's JSON.
    if (!textarea || typeof CodeMirror === "undefined" || textarea.dataset.blocks) return;
    var form = textarea.form;
    function press(action) {
      var button = form.querySelector('button[name="action"][value="' + action + '"]');
      if (button && !button.disabled) button.click();
    }
    var editor = CodeMirror.fromTextArea(textarea, {
      mode: textarea.dataset.editorMode || null,
      // Another's program shared to read: typing in it would be lost (nothing can save it).
      readOnly: textarea.readOnly,
      lineNumbers: true,
      indentUnit: 4,
      matchBrackets: true,
      viewportMargin: 50,
      // CodeMirror types into a textarea of its own: it gets the label of ours.
      screenReaderLabel: textarea.getAttribute("aria-label"),
      extraKeys: {
        "Ctrl-S": function () { press("save"); },
        "Cmd-S": function () { press("save"); },
        "Ctrl-Enter": function () { press("run"); },
        Tab: function (cm) { cm.execCommand(cm.somethingSelected() ? "indentMore" : "insertSoftTab"); },
      },
    });
    editor.setSize(null, "60vh");
    var language = form.querySelector('select[name="language"]');
    var modes = JSON.parse(textarea.dataset.editorModes || "{}");  // language -> mode
    if (language) language.addEventListener("change", function () {
      editor.setOption("mode", modes[language.value] || null);
    });
    window.robotideEditor = editor;
  });
})();
