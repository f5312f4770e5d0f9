// Blocks in the workbench: the Blockly workspace takes the textarea's place (the textarea keeps
// Blockly's JSON, which is what is saved, drafted and run), and beside it the Python the
// server makes of the blocks, read-only, refreshed as the blocks change.
//
// A run's error: the console's error lines name lines of that Python (data-line, found by the
// server, programs/error_lines.py); the Python's source map (the block each line is made for,
// sent with the Python) gives the block, which is marked (a red outline and a warning saying
// why in plain words), and the console says the same above the output, with what Python said
// kept under "details".
(function () {
  "use strict";

  function cookie(name) { return window.robotideCookie(name); }

  var ERROR_WARNING = "robotide-error";

  // Python's exceptions in a beginner's words: [pattern of its message, the words].
  function plainWords(name, message) {
    var short = name.split(".").pop();
    var m;
    if (short === "ZeroDivisionError") return gettext("you divided by zero");
    if (short === "NameError" || short === "UnboundLocalError") {
      m = /name '([^']+)'/.exec(message);
      if (m) return interpolate(gettext("the variable '%(name)s' has no value yet"), {name: m[1]}, true);
      return gettext("a variable has no value yet");
    }
    if (short === "TypeError") return gettext("a value is of the wrong kind here: for example a text, or nothing (null), where a number goes");
    if (short === "ValueError") return gettext("a value cannot be used here: for example a text that is not a number where a number goes");
    if (short === "IndexError") return gettext("a list has no item at that position");
    if (short === "KeyError") return interpolate(gettext("there is nothing called %(key)s here (for example a reading this robot does not have)"), {key: message}, true);
    if (short === "OverflowError") return gettext("a number grew too large");
    if (short === "MemoryError") return gettext("the program used more memory than it may");
    if (short === "RecursionError") return gettext("the program went too deep into itself");
    if (short === "RobotError") return interpolate(gettext("the robot could not do it (%(message)s)"), {message: message}, true);
    if (/^(Connection\w*Error|BrokenPipeError)$/.test(short)) return gettext("the connection to the robot was lost");
    return interpolate(gettext("Python reported an error (%(name)s)"), {name: short}, true);
  }
  // Not errors of the program: a stop, or an exit it chose.
  var NOT_ERRORS = ["KeyboardInterrupt", "SystemExit"];
  // The last line of a Python traceback: `Name: message`, or `Name` alone.
  var EXCEPTION = /^([A-Za-z_][\w.]*)(?:: (.*))?$/;

  // -- breakpoints on blocks and the running block, for the debugger (debug.js) -------------
  //
  // The same face as the text editor's (editor.js textBreakpoints): list(), toggleHere(),
  // onChange(listener), show(where). A breakpoint is a block's id ({"block": id}: the agent
  // finds the first line of the Python that block made); the block wears a dashed outline.
  // They are kept per program in this browser (localStorage).
  var BREAKPOINT_CLASS = "robotide-breakpoint-block";
  var MENU_ITEM = "robotide-toggle-breakpoint";

  // The line of the Python pane the program is at, marked as the text editor marks it (the
  // pane's text is the Python the debugger runs); none: the pane as plain text again.
  function markPythonLine(line) {
    var pane = document.getElementById("blocks-python");
    if (!pane || pane.classList.contains("error")) return;
    var text = pane.textContent;
    pane.textContent = "";
    if (!line) { pane.textContent = text; return; }
    var lines = text.split("\n");
    lines.forEach(function (content, index) {
      var span = document.createElement("span");
      span.textContent = content + (index < lines.length - 1 ? "\n" : "");
      if (index + 1 === line) span.className = "debug-line";
      pane.append(span);
    });
    var current = pane.querySelector(".debug-line");
    if (!current) return;
    var box = pane.getBoundingClientRect(), at = current.getBoundingClientRect();
    if (at.top < box.top || at.bottom > box.bottom) pane.scrollTop += at.top - box.top - box.height / 2;
  }

  function blockBreakpoints(workspace, programId) {
    var key = "robotide-breakpoints-" + programId;
    var ids = [];
    var listeners = [];
    var shown = null;
    try {
      ids = JSON.parse(localStorage.getItem(key) || "[]").map(function (point) { return point.block; })
        .filter(function (id) { return typeof id === "string"; });
    } catch (e) { ids = []; }

    function list() {
      return ids.filter(function (id) { return workspace.getBlockById(id); })
        .map(function (id) { return {block: id, condition: null}; });
    }
    function paint() {
      workspace.getAllBlocks(false).forEach(function (block) {
        var svg = block.getSvgRoot && block.getSvgRoot();
        if (svg) svg.classList.toggle(BREAKPOINT_CLASS, ids.indexOf(block.id) >= 0);
      });
    }
    function toggle(id) {
      if (!id) return;
      var at = ids.indexOf(id);
      if (at >= 0) ids.splice(at, 1); else ids.push(id);
      paint();
      try { localStorage.setItem(key, JSON.stringify(list())); } catch (e) { /* not kept */ }
      var now = list();
      listeners.forEach(function (listener) { listener(now); });
    }

    var registry = Blockly.ContextMenuRegistry.registry;
    if (!registry.getItem(MENU_ITEM)) {
      registry.register({
        id: MENU_ITEM,
        scopeType: Blockly.ContextMenuRegistry.ScopeType.BLOCK,
        weight: 200,
        displayText: function (scope) {
          var on = window.robotideBreakpoints && window.robotideBreakpoints.has(scope.block.id);
          return on ? gettext("Remove the breakpoint") : gettext("Toggle breakpoint");
        },
        preconditionFn: function (scope) { return scope.block.isShadow() ? "hidden" : "enabled"; },
        callback: function (scope) { window.robotideBreakpoints.toggleBlock(scope.block.id); },
      });
    }
    // Blocks loaded again (a draft restored, an undo) have new drawings: marked again.
    workspace.addChangeListener(function (event) { if (!event.isUiEvent) paint(); });
    paint();

    return {
      list: list,
      has: function (id) { return ids.indexOf(id) >= 0; },
      toggleBlock: toggle,
      toggleHere: function () {
        var selected = Blockly.common.getSelected();
        if (selected && selected.id && workspace.getBlockById(selected.id)) toggle(selected.id);
      },
      onChange: function (listener) { listeners.push(listener); },
      // The running block ({block: id}), highlighted; a pause's also brought into view.
      show: function (where, paused) {
        markPythonLine(where && where.line);
        var id = where && where.block && workspace.getBlockById(where.block) ? where.block : null;
        if (id === shown && !paused) return;
        shown = id;
        workspace.highlightBlock(id);
        if (id && paused) workspace.centerOnBlock(id);
      },
      shownBlock: function () { return shown; },
    };
  }

  document.addEventListener("DOMContentLoaded", function () {
    var bench = document.getElementById("blocks-bench");
    var textarea = document.getElementById("source");
    if (!bench || !textarea || !window.robotideBlocks) return;
    var pane = document.getElementById("blocks-python");
    var consoleBox = document.getElementById("console");
    var timer = null;
    var made = {source: null, blocks: []};  // the Python's source map, and of which text
    var asking = null;  // the request for the text as it is, while it is under way

    function showPython() {
      timer = null;
      var source = textarea.value;
      var data = new FormData();
      data.set("source", source);
      asking = fetch(bench.dataset.pythonUrl, {
        method: "POST", body: data, credentials: "same-origin",
        headers: { "X-CSRFToken": cookie("csrftoken") },
      }).then(function (response) { return response.json(); }).then(function (answer) {
        pane.textContent = answer.python || answer.error || "";
        pane.classList.toggle("error", !answer.python);
        made = {source: source, blocks: answer.blocks || []};
        return made;
      }, function () { return made; /* offline: the next change tries again */ });
      return asking;
    }

    // The source map of the text as it is (a run saves and runs it).
    function sourceMap() {
      if (made.source === textarea.value) return Promise.resolve(made);
      if (timer) { clearTimeout(timer); timer = null; }
      return showPython();
    }

    textarea.hidden = true;
    bench.hidden = false;
    var editor = window.robotideBlocksEditor = window.robotideBlocks.mount(
      document.getElementById("blocks-area"), textarea.value,
      function (json) {
        textarea.value = json;
        // The workbench's unsaved-changes and draft keeping listen for this.
        textarea.dispatchEvent(new Event("input", { bubbles: true }));
        if (timer) clearTimeout(timer);
        timer = setTimeout(showPython, 300);
      });
    showPython();
    var workspace = editor.workspace;
    window.robotideBreakpoints = blockBreakpoints(workspace, textarea.form.dataset.programId);

    // -- a run's error, marked on its block ------------------------------------------------

    var marked = null;  // the block marked, and the run whose error it is
    function unmark() {
      if (!marked) return;
      var block = workspace.getBlockById(marked.block);
      if (block) {
        block.setWarningText(null, ERROR_WARNING);
        var svg = block.getSvgRoot && block.getSvgRoot();
        if (svg) svg.classList.remove("robotide-error-block");
      }
      marked = null;
    }

    // Selected (and so focused, Blockly's keyboard then on it) and in view.
    function showBlock(id) {
      var block = id && workspace.getBlockById(id);
      if (!block) return;
      workspace.centerOnBlock(block.id);
      Blockly.common.setSelected(block);
    }

    function mark(id, warning) {
      var block = id && workspace.getBlockById(id);
      if (!block) return false;
      block.setWarningText(warning, ERROR_WARNING);
      block.getSvgRoot().classList.add("robotide-error-block");
      workspace.centerOnBlock(id);  // not selected: the keyboard's focus stays where it is
      // Its words open beside it where there is room; on a phone the bubble would cover the
      // blocks (the console says the same, and a tap on the icon opens it).
      var icon = block.getIcon && block.getIcon(Blockly.icons.IconType.WARNING);
      var room = document.getElementById("blocks-area").clientWidth >= 560;
      if (icon && icon.setBubbleVisible && room) icon.setBubbleVisible(true);
      return true;
    }

    // The block of a line of the Python: the deepest of the traceback's lines that one made
    // (a line of a helper, e.g. turn(), is no block's: the block that called it is).
    function blockOf(lines, map) {
      for (var i = lines.length - 1; i >= 0; i--) {
        var id = map.blocks[Number(lines[i].dataset.line) - 1];
        if (id) return id;
      }
      return null;
    }

    // The exception's line: the first after the traceback's last frame that reads as one.
    function exceptionAfter(line) {
      for (var next = line.nextElementSibling; next; next = next.nextElementSibling) {
        var m = EXCEPTION.exec(next.textContent);
        if (m && next.classList.contains("e")) return {name: m[1], message: m[2] || "", text: next.textContent};
      }
      return null;
    }

    function explain(run, say, original, id) {
      var note = run.querySelector(".blocks-error");
      if (!note) {
        note = document.createElement("div");
        note.className = "blocks-error";
        note.setAttribute("role", "alert");
        run.insertBefore(note, run.querySelector(".console-log"));
      }
      note.textContent = "";
      var words = document.createElement("p");
      words.textContent = say;
      note.append(words);
      if (id) {
        var show = document.createElement("button");
        show.type = "button";
        show.className = "link-button";
        show.textContent = gettext("Show the block");
        show.addEventListener("click", function () { showBlock(id); });
        words.append(" ", show);
      }
      var details = document.createElement("details");
      var summary = document.createElement("summary");
      summary.textContent = gettext("What Python said");
      var code = document.createElement("code");
      code.textContent = original;
      details.append(summary, code);
      note.append(details);
    }

    function markError(run) {
      var lines = run.querySelectorAll(".ln[data-line]");
      if (!lines.length) return;
      var last = lines[lines.length - 1];
      var error = exceptionAfter(last);
      if (!error || NOT_ERRORS.indexOf(error.name.split(".").pop()) >= 0) return;
      var key = run.dataset.run + ":" + last.dataset.line + ":" + error.text;
      if (run.dataset.blocksError === key) return;
      run.dataset.blocksError = key;
      sourceMap().then(function (map) {
        if (run.dataset.blocksError !== key) return;
        var id = blockOf(lines, map);
        var why = plainWords(error.name, error.message);
        var say = id ? interpolate(gettext("This block stopped the program: %(why)s."), {why: why}, true)
                     : interpolate(gettext("The program stopped: %(why)s."), {why: why}, true);
        unmark();
        var warning = window.robotideBlocks.wrap(say + "\n\n" + gettext("What Python said:") + " " + error.text);
        if (id && mark(id, warning)) {
          marked = {block: id, run: run.dataset.run};
        } else {
          id = null;
        }
        explain(run, say, error.text, id);
      });
    }

    // The console's lines naming the Python's lines become links to their blocks. This runs
    // before workbench.js's own observer (made first: this script comes first), which leaves
    // lines with a role alone: its links go to a text editor's lines.
    function linkLines(run) {
      run.querySelectorAll(".ln[data-line]:not([role])").forEach(function (element) {
        element.setAttribute("role", "link");
        element.tabIndex = 0;
        element.title = gettext("Show the block this line of Python was made for");
        function go() {
          sourceMap().then(function (map) { showBlock(blockOf([element], map) || (marked && marked.block)); });
        }
        element.addEventListener("click", go);
        element.addEventListener("keydown", function (event) { if (event.key === "Enter") go(); });
      });
    }

    if (consoleBox) {
      new MutationObserver(function () {
        var run = consoleBox.querySelector("#console-run[data-run]");
        if (!run) return;
        if (marked && marked.run !== run.dataset.run) unmark();  // another run: its own error
        linkLines(run);
        markError(run);
      }).observe(consoleBox, { childList: true, subtree: true });
    }
  });
})();
