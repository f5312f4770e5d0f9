// The workbench's debugger: Debug beside Run, the panel (templates/programs/_debug.html) with
// the commands, the call stack, the variables and the watches, and the program's place in the
// editor. The protocol: programs/clients/PROTOCOL.md, "The debugger".
//
// Breakpoints and the place shown are the editor's (window.robotideBreakpoints: editor.js for
// text, blocks_bench.js for blocks). Events come on the console's websocket as JSON text
// {"debug": event}, taken here before htmx would swap them as HTML; commands are POSTed to
// /runs/ID/debug. Whatever the program supplies (names, values, errors) is set as text only.
(function () {
  "use strict";

  var ONGOING = ["queued", "starting", "running"];
  var STEPS = ["continue", "step_over", "step_into", "step_out"];

  function cookie(name) { return window.robotideCookie(name); }

  document.addEventListener("DOMContentLoaded", function () {
    var form = document.getElementById("editor-form");
    var panel = document.getElementById("debug-panel");
    var debugButton = document.getElementById("bench-debug");
    if (!form || !panel || !debugButton || !window.robotideWorkbench) return;
    var code = document.getElementById("bench-code");
    var statusLine = document.getElementById("debug-status");
    var exceptionLine = document.getElementById("debug-exception");
    var stackList = document.getElementById("debug-stack");
    var localsList = document.getElementById("debug-locals");
    var globalsList = document.getElementById("debug-globals");
    var noVariables = document.getElementById("debug-variables-none");
    var watchList = document.getElementById("debug-watches");
    var watchInput = document.getElementById("debug-watch-input");
    var consoleBox = document.getElementById("console");
    var consoleSection = form.querySelector(".console");
    var buttons = {};
    panel.querySelectorAll("button[data-command]").forEach(function (button) {
      buttons[button.dataset.command] = button;
      button.addEventListener("click", function () { command(button.dataset.command); });
    });
    function breakpoints() { return window.robotideBreakpoints; }

    // -- the session: idle, starting, running, paused, ended --------------------------------

    var session = {state: "idle", run: null, pause: null, resumed: true};
    var values = {before: {}, now: {}};  // variable path -> value, at the pause before and this one
    var openPaths = {};  // the variables unfolded, kept open from pause to pause

    function setState(state) {
      session.state = state;
      statusLine.dataset.state = state;
      var paused = state === "paused";
      STEPS.forEach(function (name) { buttons[name].disabled = !paused; });
      buttons.pause.disabled = state !== "running";
      buttons.stop.disabled = ["running", "paused"].indexOf(state) < 0;
      layout();
    }
    // Debugging, the panel beside the editor (under it on narrow screens): see debug.css.
    function layout() {
      var debugging = session.state !== "idle" && !panel.hidden;
      code.classList.toggle("debugging", debugging);
      var editor = window.robotideEditor;
      if (editor && editor.getOption("lineWrapping") !== debugging) {
        // Narrower beside the panel: long lines wrap rather than hide the paused line's end.
        editor.setOption("lineWrapping", debugging);
        editor.refresh();
      }
    }
    function say(text) { statusLine.textContent = text; }

    // -- Debug ------------------------------------------------------------------------------

    var languageChoice = form.querySelector('select[name="language"]');
    var runButton = form.querySelector('button[name="action"][value="run"]');
    var noDebugger = document.getElementById("bench-no-debugger");
    var debuggable = JSON.parse(debugButton.dataset.debuggable || "[]");
    debugButton.hidden = false;
    function languageChosen() {
      var name = languageChoice ? languageChoice.value : "";
      var has = debuggable.indexOf(name) >= 0;
      debugButton.disabled = !has || runButton.disabled;
      noDebugger.hidden = has;
      if (has) debugButton.title = debugButton.dataset.title;
      else {
        var label = languageChoice.options[languageChoice.selectedIndex].textContent;
        debugButton.title = interpolate(debugButton.dataset.noDebugger, {label: label}, true);
      }
    }
    if (languageChoice) languageChoice.addEventListener("change", languageChosen);
    languageChosen();

    function spec() {
      var points = breakpoints() ? breakpoints().list() : [];
      return {breakpoints: points, watches: watches.slice()};
    }

    function debug() {
      if (debugButton.disabled || session.state === "starting") return;
      panel.hidden = false;
      session = {state: "starting", run: null, pause: null, resumed: true};
      values = {before: {}, now: {}};
      clearPause();
      setState("starting");
      say(gettext("Starting under the debugger…"));
      window.robotideWorkbench.debug(spec()).then(function (run) {
        if (!run) {
          if (session.state === "starting") { setState("idle"); say(gettext("Not started.")); }
          return;
        }
        session.run = run;
        if (session.state === "starting") { setState("running"); say(gettext("Running")); }
        watchEnd();
      });
    }
    debugButton.addEventListener("click", debug);
    document.getElementById("debug-hide").addEventListener("click", function () {
      panel.hidden = true;
      if (!live()) setState("idle"); else layout();
      debugButton.focus();
    });

    function live() { return ["starting", "running", "paused"].indexOf(session.state) >= 0; }

    // -- commands ---------------------------------------------------------------------------

    function post(body) {
      if (!session.run) return Promise.resolve(false);
      return fetch("/runs/" + encodeURIComponent(session.run) + "/debug", {
        method: "POST", credentials: "same-origin", redirect: "manual",
        body: JSON.stringify(body),
        headers: {"Content-Type": "application/json", "X-CSRFToken": csrf()},
      }).then(function (response) {
        if (response.status === 202) return true;
        return response.json().then(function (answer) { return answer.error || answer.detail; }, function () { return null; })
          .then(function (why) {
            say(interpolate(gettext("The debugger did not take it: %(why)s"), {why: why || response.status}, true));
            return false;
          });
      }, function () {
        say(gettext("Not sent: the server cannot be reached."));
        return false;
      });
    }
    // The form's token, as the page's other posts send it (the cookie's, if the form has none).
    function csrf() {
      var input = form.querySelector('input[name="csrfmiddlewaretoken"]');
      return cookie("csrftoken") || (input && input.value);
    }

    function command(name) {
      // An update while paused is answered by the pause said again: a step asked meanwhile
      // waits for it (the debugger, between the two, would not hear it).
      if (session.repause && STEPS.indexOf(name) >= 0) { session.queued = name; return; }
      if (name === "pause" ? session.state !== "running" : STEPS.indexOf(name) >= 0 && session.state !== "paused") return;
      if (name === "stop" && !live()) return;
      if (name !== "stop") {
        // Until the debugger says it goes on: no second step on the way.
        STEPS.forEach(function (step) { buttons[step].disabled = true; });
        buttons.pause.disabled = true;
      }
      var pauses = session.pauses;
      post({command: name}).then(function (taken) {
        if (session.pauses !== pauses) return;  // the next pause came before the answer did
        if (!taken) { if (session.state === "paused") setState("paused"); return; }
        if (STEPS.indexOf(name) >= 0 && session.state === "paused") running();
      });
    }

    // Breakpoints or watches changed while the run goes: the debugger is told.
    function update() {
      if (!live() || !session.run) return;
      if (session.state === "paused") {
        session.repause = true;
        clearTimeout(session.repauseTimer);
        session.repauseTimer = setTimeout(repaused, 5000);  // said again, or not: not stuck
      }
      post({command: "update", breakpoints: spec().breakpoints, watches: watches.slice()});
    }
    function repaused() {
      clearTimeout(session.repauseTimer);
      session.repause = false;
      var queued = session.queued;
      session.queued = null;
      if (queued) command(queued);
    }

    // -- the events -------------------------------------------------------------------------

    document.addEventListener("htmx:wsBeforeMessage", function (event) {
      var text = event.detail.message;
      if (typeof text !== "string" || text.lastIndexOf('{"debug"', 0) !== 0) return;
      if (!consoleSection.contains(event.target)) return;  // another socket's (a robot's)
      event.preventDefault();  // JSON, not HTML for htmx to swap
      var message;
      try { message = JSON.parse(text); } catch (e) { return; }
      if (!live()) return;  // a run not debugged here, or over
      received(message.debug || {});
    });

    function received(event) {
      if (event.state === "paused" && event.paused) paused(event);
      else if (event.state === "running") running();
      else if (event.state === "at" && breakpoints()) breakpoints().show({line: event.line, block: event.block}, false);
    }

    function running() {
      session.resumed = true;
      if (session.state !== "running") setState("running");
      say(gettext("Running"));
      if (breakpoints() && !window.robotideBlocksEditor) breakpoints().show(null);
    }

    var REASONS = {
      breakpoint: gettext("breakpoint"),
      step: gettext("step"),
      pause: gettext("paused"),
      entry: gettext("start"),
      exception: gettext("error"),
    };

    function paused(event) {
      var pause = event.paused;
      // A pause said again (after an update) compares with the same pause before it.
      if (session.resumed) values.before = values.now;
      session.resumed = false;
      session.pause = pause;
      session.pauses = (session.pauses || 0) + 1;
      values.now = {};
      panel.hidden = false;  // hidden while it ran: a pause shows it again
      setState("paused");
      var reason = REASONS[pause.reason] || pause.reason || "";
      var words = event.block ? gettext("Paused at the highlighted block: line %(line)s of its Python (%(reason)s)")
                              : gettext("Paused at line %(line)s (%(reason)s)");
      say(interpolate(words, {line: pause.line, reason: reason}, true));
      exceptionLine.hidden = !pause.exception;
      exceptionLine.textContent = pause.exception || "";
      if (breakpoints()) breakpoints().show({line: pause.line, block: event.block}, true);
      showStack(pause.stack || []);
      showVariables(localsList, pause.locals || [], "l");
      showVariables(globalsList, pause.globals || [], "g");
      localsList.hidden = document.getElementById("debug-locals-title").hidden = !(pause.locals || []).length;
      noVariables.hidden = (pause.locals || []).length + (pause.globals || []).length > 0;
      if (!noVariables.hidden) noVariables.textContent = gettext("No variables yet.");
      showWatches(pause.watches || []);
      if (session.repause) repaused();
    }

    function clearPause() {
      exceptionLine.hidden = true;
      stackList.textContent = "";
      if (breakpoints()) breakpoints().show(null);
    }

    // The run's end, as its console says it (its status's data-state).
    var endWatcher = null;
    function watchEnd() {
      if (endWatcher) endWatcher.disconnect();
      function check() {
        var status = consoleBox.querySelector('#console-run[data-run="' + session.run + '"] #run-status');
        if (!status || ONGOING.indexOf(status.dataset.state) >= 0 || !live()) return;
        endWatcher.disconnect();
        // The state as the status says it, in the page's language ("stopped": "parada")
        var label = status.querySelector(".state");
        ended(label ? label.textContent.trim() : status.dataset.state);
      }
      endWatcher = new MutationObserver(check);
      endWatcher.observe(consoleBox, {childList: true, subtree: true, attributes: true, attributeFilter: ["data-state"]});
      check();
    }
    function ended(state) {
      setState("ended");
      say(interpolate(gettext("Ended (%(state)s)"), {state: state}, true));
      if (breakpoints()) breakpoints().show(null);
      // The last pause's variables stay to be read; what is not live any more says so.
      panel.classList.add("debug-over");
    }

    // -- the stack, the variables, the watches ----------------------------------------------

    function showStack(stack) {
      stackList.textContent = "";
      stack.slice().reverse().forEach(function (frame) {  // innermost first, as debuggers list
        var item = document.createElement("li");
        var name = document.createElement("code");
        name.textContent = frame.function;
        item.append(name, " ", interpolate(gettext("line %(line)s"), {line: frame.line}, true));
        stackList.append(item);
      });
    }

    function element(tag, className, text) {
      var node = document.createElement(tag);
      if (className) node.className = className;
      if (text !== undefined && text !== null) node.textContent = String(text);
      return node;
    }

    // One line of a variable: its name, its type and its value, marked if it changed.
    function describe(variable, path) {
      var line = element("span", "var");
      line.append(element("span", "var-name", variable.name), " ",
                  element("span", "var-type", variable.type), " ",
                  element("code", "var-value", variable.value));
      values.now[path] = variable.type + ":" + variable.value;
      var hadPause = Object.keys(values.before).length > 0;
      // A watch just added is new, not changed; a variable new since the last pause is.
      var fresh = !(path in values.before);
      if (hadPause && values.before[path] !== values.now[path] && !(fresh && path.lastIndexOf("w:", 0) === 0)) {
        line.classList.add("changed");
        line.append(element("span", "var-changed", gettext("changed")));
      }
      return line;
    }

    function variableItem(variable, path) {
      var item = document.createElement("li");
      var children = variable.children;
      if (!children || !children.length && !variable.more) {
        item.append(describe(variable, path));
        return item;
      }
      var details = document.createElement("details");
      var summary = document.createElement("summary");
      summary.append(describe(variable, path));
      details.append(summary);
      details.open = !!openPaths[path];
      details.addEventListener("toggle", function () { openPaths[path] = details.open; });
      var list = element("ul", "debug-tree");
      children.forEach(function (child) { list.append(variableItem(child, path + "/" + child.name)); });
      if (variable.more) {
        list.append(element("li", "muted", interpolate(gettext("… and %(count)s more"), {count: variable.more}, true)));
      }
      details.append(list);
      item.append(details);
      return item;
    }

    function showVariables(list, variables, scope) {
      list.textContent = "";
      variables.forEach(function (variable) { list.append(variableItem(variable, scope + ":" + variable.name)); });
    }

    // -- watches: kept per program in this browser ------------------------------------------

    var watchKey = "robotide-watches-" + form.dataset.programId;
    var watches = [];
    try { watches = JSON.parse(localStorage.getItem(watchKey) || "[]").filter(function (w) { return typeof w === "string"; }); }
    catch (e) { watches = []; }
    var watchValues = {};  // expression -> its item of the last pause

    function keepWatches() {
      try { localStorage.setItem(watchKey, JSON.stringify(watches)); } catch (e) { /* not kept */ }
    }

    function showWatches(evaluated) {
      watchValues = {};
      evaluated.forEach(function (watch) { watchValues[watch.expression] = watch; });
      drawWatches();
    }

    function drawWatches() {
      watchList.textContent = "";
      watches.forEach(function (expression, index) {
        var item = element("li", "debug-watch");
        var known = watchValues[expression];
        var body = element("div", "watch-body");
        if (known && known.value) {
          body.append(variableItem(Object.assign({}, known.value, {name: expression}), "w:" + expression).firstChild);
        } else {
          body.append(element("code", "var-name", expression), " ");
          if (known && known.error) body.append(element("span", "watch-error", known.error));
          else body.append(element("span", "muted", session.state === "paused" ? gettext("(evaluated at the next pause)") : gettext("(shown at a pause)")));
        }
        var remove = element("button", "link-button watch-remove", "×");
        remove.type = "button";
        remove.setAttribute("aria-label", interpolate(gettext("Stop watching %(expression)s"), {expression: expression}, true));
        remove.title = gettext("Remove this watch");
        remove.addEventListener("click", function () {
          watches.splice(index, 1);
          keepWatches();
          drawWatches();
          update();
          watchInput.focus();
        });
        item.append(body, remove);
        watchList.append(item);
      });
    }

    function addWatch() {
      var expression = watchInput.value.trim();
      if (!expression) return;
      if (watches.indexOf(expression) < 0) watches.push(expression);
      watchInput.value = "";
      keepWatches();
      drawWatches();
      update();  // while paused, the debugger evaluates it and says the pause again
    }
    document.getElementById("debug-watch-add").addEventListener("click", addWatch);
    watchInput.addEventListener("keydown", function (event) {
      if (event.key === "Enter") { event.preventDefault(); addWatch(); }  // not the page's form
    });
    drawWatches();
    if (watches.length) panel.hidden = false;  // watches kept from before: the panel with them

    // -- breakpoints changed: the debugger told -----------------------------------------------

    function listenToBreakpoints() {
      if (!breakpoints()) return;
      breakpoints().onChange(function () { update(); });
    }
    listenToBreakpoints();

    // -- keys -------------------------------------------------------------------------------

    document.addEventListener("keydown", function (event) {
      if (event.ctrlKey || event.metaKey || event.altKey) return;
      var name = null;
      if (event.key === "F8") name = session.state === "running" ? "pause" : "continue";
      else if (event.key === "F10") name = "step_over";
      else if (event.key === "F11") name = event.shiftKey ? "step_out" : "step_into";
      else if (event.key === "F9") {
        if (event.defaultPrevented || !breakpoints()) return;  // the text editor's own F9 took it
        event.preventDefault();
        breakpoints().toggleHere();
        return;
      }
      if (!name || !live()) return;
      event.preventDefault();  // not the browser's (F11: full screen)
      command(name);
    });

    setState("idle");
  });
})();
