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
      // Breakpoints have a gutter of their own beside the line numbers (debug.js).
      gutters: ["breakpoints", "CodeMirror-linenumbers"],
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
        F9: function (cm) { breakpoints.toggle(cm.getCursor().line); },
        "Shift-F9": function (cm) { breakpoints.ask(cm.getCursor().line); },
      },
    });
    editor.setSize(null, "60vh");
    var language = form.querySelector('select[name="language"]');
    var modes = JSON.parse(textarea.dataset.editorModes || "{}");  // language -> mode
    if (language) language.addEventListener("change", function () {
      editor.setOption("mode", modes[language.value] || null);
    });
    window.robotideEditor = editor;
    var breakpoints = window.robotideBreakpoints = textBreakpoints(editor, form.dataset.programId);
  });

  // -- breakpoints and the paused line, for the debugger (debug.js) ------------------------
  //
  // A breakpoint is a gutter marker on a line: CodeMirror keeps it on its line as text is
  // typed above it (the marker lives on the line's handle), and drops it with the line. They
  // are kept per program in this browser (localStorage), as lines.
  function textBreakpoints(editor, programId) {
    var key = "robotide-breakpoints-" + programId;
    var handles = [];  // [{handle, condition}]
    var listeners = [];
    var asking = null;  // the condition's line widget, while it is open
    var shown = null;  // the line handle shown as the program's place

    function lineOf(point) { return editor.getLineNumber(point.handle); }
    function alive() { return handles.filter(function (point) { return lineOf(point) !== null; }); }
    function find(line) {
      var handle = editor.getLineHandle(line);
      return handles.filter(function (point) { return point.handle === handle; })[0];
    }
    function list() {
      handles = alive();
      return handles.map(function (point) { return {line: lineOf(point) + 1, condition: point.condition}; })
        .sort(function (a, b) { return a.line - b.line; });
    }
    function keep() {
      try { localStorage.setItem(key, JSON.stringify(list())); } catch (e) { /* private mode: not kept */ }
    }
    function changed() {
      keep();
      var now = list();
      listeners.forEach(function (listener) { listener(now); });
    }
    function marker(condition) {
      var dot = document.createElement("span");
      dot.className = "breakpoint" + (condition ? " conditional" : "");
      dot.textContent = condition ? "◆" : "●";
      dot.title = condition ? interpolate(gettext("Breakpoint: pauses here when %(condition)s"), {condition: condition}, true)
                            : gettext("Breakpoint: the debugger pauses here");
      return dot;
    }
    function set(line, condition) {
      var point = find(line);
      if (!point) { point = {handle: editor.getLineHandle(line)}; handles.push(point); }
      point.condition = condition || null;
      editor.setGutterMarker(point.handle, "breakpoints", marker(point.condition));
    }
    function remove(line) {
      var point = find(line);
      if (!point) return;
      editor.setGutterMarker(point.handle, "breakpoints", null);
      handles.splice(handles.indexOf(point), 1);
    }
    function toggle(line) {
      if (find(line)) remove(line); else set(line, null);
      changed();
    }

    function closeAsking() {
      if (!asking) return;
      asking.clear();
      asking = null;
    }
    // The condition: a small form under the line (not a prompt), keyboard first.
    function ask(line) {
      closeAsking();
      var point = find(line);
      var box = document.createElement("div");
      box.className = "breakpoint-form";
      box.setAttribute("role", "group");
      var id = "breakpoint-condition-" + line;
      var label = document.createElement("label");
      label.htmlFor = id;
      label.textContent = interpolate(gettext("Pause at line %(line)s only when"), {line: line + 1}, true);
      var input = document.createElement("input");
      input.id = id;
      input.type = "text";
      input.spellcheck = false;
      input.autocomplete = "off";
      input.placeholder = gettext("a Python condition, e.g. distance < 1.0");
      input.value = (point && point.condition) || "";
      box.setAttribute("aria-label", gettext("Breakpoint condition"));
      function button(text, action) {
        var b = document.createElement("button");
        b.type = "button";
        b.textContent = text;
        b.addEventListener("click", action);
        return b;
      }
      function done() { closeAsking(); editor.focus(); }
      function save() { set(line, input.value.trim()); changed(); done(); }
      var buttons = document.createElement("span");
      buttons.className = "breakpoint-form-buttons";
      buttons.append(button(gettext("Set"), save));
      if (point) buttons.append(button(gettext("Remove"), function () { remove(line); changed(); done(); }));
      buttons.append(button(gettext("Cancel"), done));
      input.addEventListener("keydown", function (event) {
        // Enter would submit the page's form; Esc would count towards Esc Esc (stop the run).
        if (event.key === "Enter") { event.preventDefault(); save(); }
        else if (event.key === "Escape") { event.preventDefault(); event.stopPropagation(); done(); }
      });
      box.append(label, input, buttons);
      asking = editor.addLineWidget(line, box, {coverGutter: false, noHScroll: true});
      // After the click that opened it is done with (CodeMirror focuses itself on it).
      setTimeout(function () { input.focus(); }, 0);
    }

    editor.on("gutterClick", function (cm, line, gutter, event) {
      if (event.button !== 0) return;  // the right button's is the context menu's (below)
      if (event.shiftKey) ask(line); else toggle(line);
    });
    editor.on("gutterContextMenu", function (cm, line, gutter, event) {
      event.preventDefault();
      ask(line);
    });
    // Lines put in at a line's very start push its text down: its breakpoint goes with the
    // text (CodeMirror keeps a line's handle on the first of the lines it is split into).
    function pushedDown(change) {
      var lines = change.text.length - 1;
      if (!lines || change.from.ch !== 0 || change.from.line !== change.to.line || change.to.ch !== 0) return;
      var handle = editor.getLineHandle(change.from.line);
      handles.forEach(function (point) {
        if (point.handle !== handle) return;
        editor.setGutterMarker(handle, "breakpoints", null);
        point.handle = editor.getLineHandle(change.from.line + lines);
        editor.setGutterMarker(point.handle, "breakpoints", marker(point.condition));
      });
    }
    editor.on("change", function (cm, change) {
      pushedDown(change);
      var before = JSON.stringify(handles.map(lineOf));
      if (JSON.stringify(alive().map(lineOf)) !== before) changed(); else keep();
    });

    try {
      JSON.parse(localStorage.getItem(key) || "[]").forEach(function (point) {
        if (point.line >= 1 && point.line <= editor.lineCount()) set(point.line - 1, point.condition);
      });
    } catch (e) { /* none kept, or not readable: none */ }

    return {
      list: list,
      toggle: toggle,
      ask: ask,
      toggleHere: function () { toggle(editor.getCursor().line); },
      onChange: function (listener) { listeners.push(listener); },
      // The program's place (1-based line), shown and scrolled to; null: none.
      show: function (where) {
        if (shown) editor.removeLineClass(shown, "wrap", "debug-line");
        shown = where && where.line ? editor.getLineHandle(where.line - 1) : null;
        if (!shown) return;
        editor.addLineClass(shown, "wrap", "debug-line");
        editor.scrollIntoView({line: where.line - 1, ch: 0}, 80);
      },
      // The line shown now (1-based), or null.
      shownLine: function () { var line = shown && editor.getLineNumber(shown); return line === null || !shown ? null : line + 1; },
    };
  }
})();
