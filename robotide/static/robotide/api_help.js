// Robot API help in the code editor (CodeMirror 5): completion of the API's calls and a
// tooltip on each, from the one description of the API (programs/robot_api_spec.py, served
// as JSON per language by programs/api_help.py).
//
//   robotideApiHelp.attach(editor, "python", "/help/robot-api/python.json")
//
// Ctrl-Space after the robot object (bot., $bot->, bot:, robot::, `robot `) or at the start of
// a line offers the calls, each with its signature and summary, and the selected one's doc
// beside the list; on a call's name it shows that call's help instead, as F1 does. Pointing
// at a call's name shows the same help. Nothing takes the keyboard's focus from the editor:
// Esc closes the list or the help. Calling attach again (another language) replaces the help.
//
// Loaded with data-help (the help page's URL; LANGUAGE.json beside it is the JSON) on its
// script tag, it attaches itself to the workbench's editor and follows its language choice.
// Completion needs CodeMirror's show-hint addon: loaded from data-show-hint if not already.
(function () {
  "use strict";

  var script = document.currentScript;
  var TIP_ID = "robotide-api-help-tip";
  var HOVER_DELAY = 350;  // ms the pointer rests on a name before its help shows
  var cache = {};  // url -> Promise of the help

  function load(url) {
    if (!cache[url]) {
      cache[url] = fetch(url, { credentials: "same-origin", headers: { Accept: "application/json" } })
        .then(function (response) {
          if (!response.ok) throw new Error("Robot API help: " + response.status + " for " + url);
          return response.json();
        });
      cache[url].catch(function () { delete cache[url]; });  // try again next time
    }
    return cache[url];
  }

  function showHintReady() {
    if (CodeMirror.showHint) return Promise.resolve();
    var src = script && script.dataset.showHint;
    if (!src) return Promise.reject(new Error("Robot API help: CodeMirror's show-hint is not loaded"));
    return new Promise(function (resolve, reject) {
      var tag = document.createElement("script");
      tag.src = src;
      tag.onload = resolve;
      tag.onerror = reject;
      document.head.appendChild(tag);
    });
  }

  function escapeRe(text) { return text.replace(/[.*+?^${}()|[\]\\\/-]/g, "\\$&"); }

  function element(tag, className, text) {
    var node = document.createElement(tag);
    if (className) node.className = className;
    if (text) node.textContent = text;
    return node;
  }

  // -- what is at a place in the program -------------------------------------------------

  // The robot objects a program names: those it connects (`bot = robot.Robot()`...), and the
  // name the help itself uses; remembered until the text changes.
  function objects(cm, state) {
    var generation = cm.changeGeneration();
    if (state.objects && state.objectsAt === generation) return state.objects;
    var names = [state.help.object];
    var re = new RegExp(state.help.objects, "g"), text = cm.getValue(), m;
    while ((m = re.exec(text))) {
      if (names.indexOf(m[1]) < 0) names.push(m[1]);
      if (!m[0]) re.lastIndex++;
    }
    state.objects = names;
    state.objectsAt = generation;
    return names;
  }

  function accessorRe(help) {
    return help.accessor === " " ? "\\s+" : escapeRe(help.accessor);
  }

  // The call whose name is at `pos` (the cursor may be just after it): {call, from, to}.
  function callAt(cm, state, pos) {
    var help = state.help, line = cm.getLine(pos.line), m;
    var words = help.calls.filter(function (c) { return c.name !== "connect"; })
      .map(function (c) { return c.word; })
      .sort(function (a, b) { return b.length - a.length; })
      .map(function (w) { return escapeRe(w).replace(/ /g, "\\s+"); });
    var objs = objects(cm, state).map(escapeRe).join("|");
    var re = new RegExp("(?:^|[^\\w$])(?:" + objs + ")" + accessorRe(help) + "(" + words.join("|") + ")(?![\\w])", "gd");
    var found = null;
    function consider(start, end, call) {
      if (!found && call && pos.ch >= start && pos.ch <= end) found = { call: call, from: start, to: end };
    }
    while ((m = re.exec(line))) {
      var word = m[1].replace(/\s+/g, " ");
      consider(m.indices[1][0], m.indices[1][1], pickCall(cm, help, pos.line, m.indices[1][1], word));
    }
    var ctor = new RegExp(help.connects, "gd");
    while ((m = ctor.exec(line))) {
      if (!m[0]) { ctor.lastIndex++; continue; }
      consider(m.indices[1][0], m.indices[1][1], help.calls.find(function (c) { return c.name === "connect"; }));
    }
    return found;
  }

  // The shell's `robot sensors` is two calls (all readings, or one by NAME): the words after it.
  function pickCall(cm, help, line, end, word) {
    var same = help.calls.filter(function (c) { return c.word === word && c.name !== "connect"; });
    if (same.length < 2) return same[0];
    var rest = cm.getLine(line).slice(end).trim();
    return same.find(function (c) { return (c.params.length > 0) === (rest !== "" && !/^[;|&)]/.test(rest)); }) || same[0];
  }

  // What completion can offer at the cursor: {from, to, typed, list of [call, text to insert]}.
  function completions(cm, state) {
    var help = state.help, cur = cm.getCursor(), before = cm.getLine(cur.line).slice(0, cur.ch);
    var objs = objects(cm, state);
    var wordChars = help.accessor === " " ? "[\\w ]" : "\\w";
    var after = new RegExp("(?:^|[^\\w$])(?:" + objs.map(escapeRe).join("|") + ")" + accessorRe(help) + "(" + wordChars + "*)$").exec(before);
    var items = [], typed;
    if (after) {
      typed = after[1].replace(/\s+/g, " ").toLowerCase();
      help.calls.forEach(function (c) {
        if (c.name !== "connect" && c.word.toLowerCase().indexOf(typed) === 0) items.push([c, c.insert]);
      });
      return { from: CodeMirror.Pos(cur.line, cur.ch - after[1].length), to: cur, typed: typed, items: items };
    }
    var start = /^(\s*)([$\w]*)$/.exec(before);
    if (!start) return null;
    typed = start[2].toLowerCase();
    var prefix = objs[objs.length > 1 ? 1 : 0] + help.accessor;  // the program's own name first
    help.calls.forEach(function (c) {
      var text = c.name === "connect" ? c.insert : prefix + c.insert;
      if (c.word.toLowerCase().indexOf(typed) === 0 || text.toLowerCase().indexOf(typed) === 0) items.push([c, text]);
    });
    return { from: CodeMirror.Pos(cur.line, start[1].length), to: cur, typed: typed, items: items };
  }

  // -- the tooltip ---------------------------------------------------------------------

  function tip() {
    var node = document.getElementById(TIP_ID);
    if (!node) {
      node = element("div", "api-help-tip");
      node.id = TIP_ID;
      node.setAttribute("role", "tooltip");
      node.hidden = true;
      document.body.appendChild(node);
    }
    return node;
  }

  function fillTip(node, call, help) {
    node.textContent = "";
    node.appendChild(element("code", "api-help-signature", call.signature));
    node.appendChild(element("p", "api-help-summary", call.summary));
    if (call.params.length) {
      var list = element("dl", "api-help-params");
      call.params.forEach(function (p) {
        list.appendChild(element("dt", "", p.name));
        var text = (p.unit ? p.unit + " · " : "") + p.meaning + (p.default !== null ? " " + interpolate(gettext("(default: %(default)s)"), {default: p.default}, true) : "");
        list.appendChild(element("dd", "", text));
      });
      node.appendChild(list);
    }
    node.appendChild(element("p", "api-help-returns", interpolate(gettext("Returns %(returns)s."), {returns: call.returns}, true)));
    node.appendChild(element("p", "api-help-doc", call.doc));
    if (call.note) node.appendChild(element("p", "api-help-note", help.label + ": " + call.note + "."));
    var example = element("p", "api-help-example", gettext("Example:") + " ");
    example.appendChild(element("code", "", call.example));
    node.appendChild(example);
  }

  function placeTip(node, left, top, below) {
    node.hidden = false;
    var width = node.offsetWidth, height = node.offsetHeight;
    var maxLeft = window.scrollX + document.documentElement.clientWidth - width - 8;
    node.style.left = Math.max(window.scrollX + 4, Math.min(left, maxLeft)) + "px";
    var y = top;
    if (below !== undefined && y + height > window.scrollY + window.innerHeight) y = below - height;  // above the line
    node.style.top = Math.max(window.scrollY + 4, y) + "px";
  }

  function showTip(cm, state, found, byKeyboard) {
    var node = tip();
    fillTip(node, found.call, state.help);
    node.setAttribute("aria-live", byKeyboard ? "polite" : "off");
    var start = cm.charCoords(CodeMirror.Pos(found.line, found.from), "page");
    placeTip(node, start.left, start.bottom + 4, start.top - 4);
    node.dataset.for = found.line + ":" + found.from;
    state.tipShown = true;
    state.keyboardTip = byKeyboard;  // stays until the cursor leaves the name, not the pointer
    cm.getInputField().setAttribute("aria-describedby", TIP_ID);
  }

  function hideTip(cm, state) {
    if (!state.tipShown) return;
    state.tipShown = state.keyboardTip = false;
    tip().hidden = true;
    cm.getInputField().removeAttribute("aria-describedby");
  }

  // -- keys, completion, pointing ------------------------------------------------------

  function helpAtCursor(cm, state) {
    var pos = cm.getCursor();
    var found = callAt(cm, state, pos);
    if (!found) return false;
    found.line = pos.line;
    showTip(cm, state, found, true);
    return true;
  }

  function complete(cm, state) {
    var offer = completions(cm, state);
    var pos = cm.getCursor(), on = callAt(cm, state, pos);
    var onlyItself = offer && offer.items.length === 1 && offer.items[0][0].word.toLowerCase() === offer.typed;
    if (on && (on.to > pos.ch || !offer || !offer.items.length || onlyItself)) {
      on.line = pos.line;
      showTip(cm, state, on, true);
      return;
    }
    if (!offer || !offer.items.length) return;
    hideTip(cm, state);
    cm.showHint({
      hint: function (cm) {
        var now = state.help && completions(cm, state);
        if (!now || !now.items.length) return null;
        var data = { from: now.from, to: now.to, list: now.items.map(function (item) { return entry(item[0], item[1]); }) };
        CodeMirror.on(data, "select", function (completion, node) { describeSelected(cm, state, completion, node); });
        CodeMirror.on(data, "close", function () { hideTip(cm, state); });
        return data;
      },
      completeSingle: false,
      closeCharacters: state.help.accessor === " " ? /[()[\]{};,|&]/ : /[\s()[\]{};:>,]/,
    });
  }

  function entry(call, text) {
    return {
      text: text.replace("|", ""),
      displayText: call.word,
      call: call,
      render: function (node) {
        node.appendChild(element("span", "api-help-name", call.signature));
        node.appendChild(element("span", "api-help-line", call.summary));
        node.title = call.signature;
      },
      hint: function (cm, data, completion) {
        var at = text.indexOf("|");
        cm.replaceRange(completion.text, data.from, data.to, "complete");
        cm.setCursor(CodeMirror.Pos(data.from.line, data.from.ch + at));
      },
    };
  }

  // The selected completion's whole help, beside the list.
  function describeSelected(cm, state, completion, node) {
    var list = node.parentNode, box = list.getBoundingClientRect(), row = node.getBoundingClientRect();
    var tipNode = tip();
    fillTip(tipNode, completion.call, state.help);
    tipNode.setAttribute("aria-live", "off");  // the list itself says which one is selected
    placeTip(tipNode, window.scrollX + box.right + 4, window.scrollY + row.top);
    state.tipShown = true;
    state.keyboardTip = false;
  }

  function onMouseMove(cm, state, event) {
    clearTimeout(state.hoverTimer);
    if (!state.help || cm.state.completionActive || state.keyboardTip) return;
    var x = event.clientX, y = event.clientY;
    state.hoverTimer = setTimeout(function () {
      // Ctrl-Space or F1 may have come since the mouse moved: their tip stays.
      if (cm.state.completionActive || state.keyboardTip) return;
      var pos = cm.coordsChar({ left: x, top: y }, "window");
      var box = cm.charCoords(pos, "window");
      var over = y >= box.top && y <= box.bottom && Math.abs(x - box.left) < 12;
      var found = over && callAt(cm, state, pos);
      if (found && pos.ch < found.to + (pos.sticky === "before" ? 1 : 0)) {
        found.line = pos.line;
        if (!(state.tipShown && tip().dataset.for === found.line + ":" + found.from)) showTip(cm, state, found, false);
      } else {
        hideTip(cm, state);
      }
    }, HOVER_DELAY);
  }

  // -- attach, detach --------------------------------------------------------------------

  function detach(cm) {
    var state = cm.state.robotideApiHelp;
    if (!state) return;
    clearTimeout(state.hoverTimer);
    hideTip(cm, state);
    if (cm.state.completionActive) cm.state.completionActive.close();
    cm.removeKeyMap(state.keys);
    state.off.forEach(function (undo) { undo(); });
    state.gone = true;
    delete cm.state.robotideApiHelp;
  }

  function attach(cm, language, url) {
    detach(cm);
    var state = { language: language, help: null, off: [], tipShown: false };
    cm.state.robotideApiHelp = state;
    function when(fn) {  // run fn once the help is here, if it is still this help
      return function (cm) {
        if (state.help) return fn(cm, state);
        state.ready.then(function () { if (!state.gone) fn(cm, state); });
      };
    }
    state.keys = {
      "Ctrl-Space": when(complete),
      F1: when(function (cm, state) { helpAtCursor(cm, state); }),
      Esc: function (cm) {
        if (!state.tipShown) return CodeMirror.Pass;
        hideTip(cm, state);
        return CodeMirror.Pass;  // the workbench's Esc-then-Tab still leaves the editor
      },
    };
    cm.addKeyMap(state.keys);
    function on(target, type, handler) {
      if (target.addEventListener) {
        target.addEventListener(type, handler);
        state.off.push(function () { target.removeEventListener(type, handler); });
      } else {
        cm.on(type, handler);
        state.off.push(function () { cm.off(type, handler); });
      }
    }
    var wrapper = cm.getWrapperElement();
    on(wrapper, "mousemove", function (event) { onMouseMove(cm, state, event); });
    on(wrapper, "mouseleave", function (event) {
      clearTimeout(state.hoverTimer);
      if (event.relatedTarget && event.relatedTarget.closest && event.relatedTarget.closest("#" + TIP_ID)) return;
      if (!cm.state.completionActive && !state.keyboardTip) hideTip(cm, state);
    });
    on(tip(), "mouseleave", function () {
      if (!cm.state.completionActive && !state.keyboardTip) hideTip(cm, state);
    });
    on(cm, "cursorActivity", function () {
      if (!state.tipShown || cm.state.completionActive) return;
      var pos = cm.getCursor(), shown = tip().dataset.for.split(":");
      var found = state.help && callAt(cm, state, pos);
      if (!found || String(pos.line) !== shown[0] || String(found.from) !== shown[1]) hideTip(cm, state);
    });
    on(cm, "blur", function () { if (!cm.state.completionActive) hideTip(cm, state); });
    on(cm, "scroll", function () { hideTip(cm, state); });
    state.ready = Promise.all([load(url), showHintReady()]).then(function (results) {
      if (!state.gone) state.help = results[0];
      return state.help;
    });
    state.ready.catch(function (error) { console.warn(error.message || error); });
    return state.ready;
  }

  window.robotideApiHelp = { attach: attach, detach: detach };

  // Loaded with data-help on its tag: attach to the workbench's editor and follow its language.
  function autoAttach() {
    var base = script && script.dataset.help;
    var cm = window.robotideEditor;
    if (!base || !cm || cm.state.robotideApiHelpAuto) return;
    cm.state.robotideApiHelpAuto = true;
    var form = cm.getTextArea && cm.getTextArea().form;
    var choice = form && form.querySelector('select[name="language"]');
    function follow() {
      var language = choice ? choice.value : cm.getTextArea().dataset.language;
      if (language) attach(cm, language, base + encodeURIComponent(language) + ".json").catch(function () { detach(cm); });
    }
    follow();
    if (choice) choice.addEventListener("change", follow);
  }
  // A deferred script runs before DOMContentLoaded, when editor.js has not made the editor yet.
  if (document.readyState !== "complete") {
    document.addEventListener("DOMContentLoaded", autoAttach);
    window.addEventListener("load", autoAttach);
  }
  autoAttach();
})();
