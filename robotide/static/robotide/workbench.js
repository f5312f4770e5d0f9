// The workbench: save, run, watch and stop without leaving the program page.
//
// Without scripts the page is a plain form that posts to the program page (save) and goes to
// the run's page (run). With scripts, the same buttons and keys stay here: a save is a
// request answered in JSON; a run answers its console, which streams the run's output over
// the run's websocket (htmx's ws extension); the robot panel beside the editor is the chosen
// robot's live view. Nothing typed is lost to an expired sign-in or a conflicting save.
(function () {
  "use strict";

  function cookie(name) { return window.robotideCookie(name); }

  document.addEventListener("DOMContentLoaded", function () {
    var form = document.getElementById("editor-form");
    if (!form || !form.dataset.saveUrl) return;
    var editor = window.robotideEditor;  // editor.js, loaded first
    var textarea = document.getElementById("source");
    var language = form.querySelector('select[name="language"]');
    var robotChoice = document.getElementById("bench-robot-choice");
    var base = form.querySelector('input[name="base_revision"]');
    var stateNote = document.getElementById("save-state");
    var consoleBox = document.getElementById("console");
    var stopButton = document.getElementById("bench-stop");
    var estopButton = document.getElementById("bench-estop");
    var conflictBox = document.getElementById("conflict");
    var canEdit = form.dataset.canEdit === "true";
    var busy = false;

    form.querySelector(".console").hidden = false;
    document.getElementById("bench-panel").hidden = false;
    stopButton.hidden = estopButton.hidden = false;

    function text() { return editor ? editor.getValue() : textarea.value; }
    function snapshot() { return (language ? language.value : "") + "\n" + text(); }
    var saved = snapshot();
    function dirty() { return canEdit && snapshot() !== saved; }
    function say(message, kind) {
      stateNote.textContent = message;
      stateNote.dataset.kind = kind || "";
    }
    function showDirty() { if (dirty()) say(gettext("Unsaved changes"), "dirty"); else if (stateNote.dataset.kind === "dirty") say(gettext("Saved"), "saved"); }
    if (editor) editor.on("change", showDirty); else textarea.addEventListener("input", showDirty);
    if (language) language.addEventListener("change", showDirty);

    function post(url, action, fields) {
      if (editor) editor.save();
      var data = new FormData(form);
      data.set("action", action);
      Object.keys(fields || {}).forEach(function (name) { data.set(name, fields[name]); });
      // The header's token, read now: the form's may be stale after signing in again.
      data.delete("csrfmiddlewaretoken");
      return fetch(url, {
        method: "POST", body: data, credentials: "same-origin", redirect: "manual",
        headers: { "X-CSRFToken": cookie("csrftoken"), "X-Requested-With": "fetch" },
      });
    }

    // What every answer may say instead of its own: signed out, a conflict, an error.
    function trouble(response) {
      if (response.type === "opaqueredirect" || response.status === 401) {
        signedOut();
        return Promise.resolve(true);
      }
      if (response.status === 409) return response.json().then(function (answer) { showConflict(answer); return true; });
      if (!response.ok) {
        return response.json().then(function (answer) { say(answer.error || gettext("Failed"), "error"); return true; },
          function () { say(interpolate(gettext("The server answered %(status)s"), {status: response.status}, true), "error"); return true; });
      }
      return Promise.resolve(false);
    }

    function saveAnswered(revision) {
      saved = snapshot();
      if (revision) {
        base.value = revision;
        var note = document.getElementById("revision-note");
        if (note) note.textContent = interpolate(gettext("revision %(revision)s, just now"), {revision: revision}, true);
      }
      conflictBox.hidden = true;
      say(revision ? interpolate(gettext("Saved (revision %(revision)s)"), {revision: revision}, true) : gettext("Saved"), "saved");
    }

    function save() {
      if (!canEdit || busy) return Promise.resolve(false);
      busy = true;
      say(gettext("Saving…"), "busy");
      return post(form.dataset.saveUrl, "save").then(function (response) {
        return trouble(response).then(function (failed) {
          if (failed) return false;
          return response.json().then(function (answer) { saveAnswered(answer.revision); return true; });
        });
      }, offline).finally(function () { busy = false; });
    }
    // An exercise's Check (check_panel.js) saves as Save does, then checks what was saved;
    // the debugger (debug.js) starts as Run does, under the debugger with its spec.
    window.robotideWorkbench = { save: save, debug: function (spec) { return run(spec); } };

    // Saves and starts the run (a debugger's `spec`: under the debugger); its id, or null.
    function run(spec) {
      if (busy) return Promise.resolve(null);
      busy = true;
      say(canEdit ? gettext("Saving and starting…") : gettext("Starting…"), "busy");
      var fields = spec ? {debug: JSON.stringify(spec)} : null;
      return post(form.dataset.startUrl, spec ? "debug" : "run", fields).then(function (response) {
        return trouble(response).then(function (failed) {
          if (failed) return null;
          if (canEdit) saveAnswered(response.headers.get("X-Revision"));
          else say(gettext("Started"), "saved");
          mySimMade(response.headers.get("X-Robot"));
          var id = response.headers.get("X-Run");
          return response.text().then(function (html) { showRun(id, html); return id; });
        });
      }, offline).finally(function () { busy = false; });
    }

    function offline() { say(gettext("Not sent: the server cannot be reached. Your text is still here."), "error"); return false; }

    function signedOut() {
      say("", "error");
      // The translation is ours (the catalog), not user input: safe as HTML.
      stateNote.innerHTML = gettext('Your sign-in has expired; your text is kept here. <a href="/accounts/login/?next=/" target="_blank" rel="noopener">Sign in again</a> (a new tab), then come back: it is saved then.');
      window.addEventListener("focus", function retry() {
        window.removeEventListener("focus", retry);
        save();
      });
    }

    function showConflict(answer) {
      say(interpolate(gettext("Not saved: someone saved revision %(revision)s since you opened it"), {revision: answer.revision}, true), "error");
      conflictBox.hidden = false;
      conflictBox.textContent = "";
      var note = document.createElement("p");
      note.textContent = interpolate(gettext("Revision %(revision)s was saved after you opened this program. Nothing was overwritten. What differs from it:"), {revision: answer.revision}, true);
      var diff = document.createElement("pre");
      diff.className = "diff";
      diff.textContent = answer.diff;
      var keep = document.createElement("button");
      keep.type = "button";
      keep.textContent = gettext("Save mine over it");
      keep.addEventListener("click", function () { base.value = answer.revision; save(); });
      conflictBox.append(note, diff, keep);
    }

    // -- the console ----------------------------------------------------------------------

    var current = null;  // the console's run element
    var marked = null;  // the editor line marked as the error's
    function mark(line) {
      if (!editor) return;
      if (marked !== null) editor.removeLineClass(marked, "wrap", "error-line");
      marked = line === null ? null : line - 1;
      if (marked !== null) editor.addLineClass(marked, "wrap", "error-line");
    }
    function goToLine(line) {
      mark(line);
      if (editor) {
        editor.setCursor({ line: line - 1, ch: 0 });
        editor.scrollIntoView(null, 80);
        editor.focus();
      }
    }
    // An error line of the console points into the program (the server found the place):
    // it becomes a link to that line, and the last one marks the line in the editor.
    function linkErrorLines() {
      var fresh = consoleBox.querySelectorAll(".ln[data-line]:not([role])");
      fresh.forEach(function (element) {
        var line = Number(element.dataset.line);
        element.setAttribute("role", "link");
        element.tabIndex = 0;
        element.title = interpolate(gettext("Go to line %(line)s of the program"), {line: line}, true);
        element.addEventListener("click", function () { goToLine(line); });
        element.addEventListener("keydown", function (event) { if (event.key === "Enter") goToLine(line); });
      });
      if (fresh.length) mark(Number(fresh[fresh.length - 1].dataset.line));
    }
    // The console's websocket, open since the page loaded, brings the run (it was attached
    // before the answer came). Only when it is not open does the answer's console open the
    // run's own websocket.
    var consoleSection = form.querySelector(".console");
    var consoleOpen = false;
    consoleSection.addEventListener("htmx:wsOpen", function () { consoleOpen = true; });
    consoleSection.addEventListener("htmx:wsClose", function () { consoleOpen = false; });
    function shown(id) { return consoleBox.querySelector('#console-run[data-run="' + id + '"]'); }
    function showRun(id, html) {
      if (shown(id)) return;
      function fallback() {
        if (shown(id)) return;
        var place = consoleBox.querySelector("#console-run");
        place.outerHTML = html;
        if (window.htmx) window.htmx.process(consoleBox);
      }
      if (consoleOpen) setTimeout(fallback, 1500); else fallback();
    }
    function runOngoing() {
      var status = current && current.querySelector("#run-status");
      return status && ["queued", "starting", "running"].indexOf(status.dataset.state) >= 0;
    }
    // Follow the output, and know when the run ends.
    new MutationObserver(function () {
      var run = consoleBox.querySelector("#console-run[data-run]");
      if (run !== current) { current = run; mark(null); }
      var log = consoleBox.querySelector(".console-log");
      if (log) log.scrollTop = log.scrollHeight;
      linkErrorLines();
      stopButton.disabled = !runOngoing();
    }).observe(consoleBox, { childList: true, subtree: true, attributes: true, attributeFilter: ["data-state"] });

    function stop() {
      if (!current || !runOngoing()) return;
      say(gettext("Stopping…"), "busy");
      fetch(current.dataset.stopUrl, {
        method: "POST", credentials: "same-origin", redirect: "manual",
        headers: { "X-CSRFToken": cookie("csrftoken"), "HX-Request": "true" },
      }).then(function (response) { trouble(response).then(function (failed) { if (!failed) say(gettext("Stopped"), "saved"); }); }, offline);
    }

    function estop() {
      var data = new FormData();
      data.set("via", "workbench");
      fetch("/robots/" + encodeURIComponent(robotChoice.value) + "/estop", {
        method: "POST", body: data, credentials: "same-origin", redirect: "manual",
        headers: { "X-CSRFToken": cookie("csrftoken"), "HX-Request": "true" },
      }).then(function (response) {
        if (response.type === "opaqueredirect") { signedOut(); return; }
        response.text().then(function (text) { say(text || interpolate(gettext("Emergency stop: %(status)s"), {status: response.status}, true), "error"); });
      }, offline);
    }

    stopButton.addEventListener("click", stop);
    estopButton.addEventListener("click", estop);
    form.addEventListener("submit", function (event) {
      var action = event.submitter && event.submitter.value;
      if (action === "save") { event.preventDefault(); save(); }
      else if (action === "run") { event.preventDefault(); run(null); }
      else saved = snapshot();  // save as: a page change the user asked for
    });

    // -- keys -----------------------------------------------------------------------------

    var lastEscape = 0;
    document.addEventListener("keydown", function (event) {
      var mod = event.ctrlKey || event.metaKey;
      if (mod && (event.key === "s" || event.key === "S")) { event.preventDefault(); save(); }
      else if (mod && event.key === "Enter") { event.preventDefault(); run(null); }
      else if (event.key === "Escape") {
        if (event.timeStamp - lastEscape < 800) { stop(); lastEscape = 0; }
        else lastEscape = event.timeStamp;
      }
    });
    if (editor) {
      editor.setOption("extraKeys", Object.assign({}, editor.getOption("extraKeys"), {
        "Ctrl-S": save, "Cmd-S": save, "Ctrl-Enter": function () { run(null); }, "Cmd-Enter": function () { run(null); },
        // Esc then Tab leaves the editor, so the keyboard is never trapped in it.
        Esc: function (cm) { cm.state.leaving = true; setTimeout(function () { cm.state.leaving = false; }, 1500); },
        Tab: function (cm) {
          if (cm.state.leaving) { cm.state.leaving = false; cm.getInputField().blur(); robotChoice.focus(); return; }
          cm.execCommand(cm.somethingSelected() ? "indentMore" : "insertSoftTab");
        },
      }));
    }

    // -- drafts: what is typed reaches the server every few seconds, apart from revisions --

    var DRAFT_EVERY = 3000;  // ms after the last change
    var drafted = saved, draftTimer = null;
    function keepDraft() {
      draftTimer = null;
      if (!dirty() || snapshot() === drafted) return;
      var text = snapshot();
      post(form.dataset.draftUrl, "draft").then(function (response) {
        if (response.status === 204) drafted = text;
      }, function () { /* offline: the next change tries again */ });
    }
    function draftSoon() {
      if (!canEdit) return;
      if (draftTimer) clearTimeout(draftTimer);
      draftTimer = setTimeout(keepDraft, DRAFT_EVERY);
    }
    if (editor) editor.on("change", draftSoon); else textarea.addEventListener("input", draftSoon);
    if (language) language.addEventListener("change", draftSoon);

    // A tab closed (or a browser quitting) sends what the timer had not sent yet.
    window.addEventListener("pagehide", function () {
      if (!dirty() || snapshot() === drafted || !navigator.sendBeacon) return;
      if (editor) editor.save();
      var data = new FormData(form);
      data.set("action", "draft");
      data.set("csrfmiddlewaretoken", cookie("csrftoken"));
      navigator.sendBeacon(form.dataset.draftUrl, data);
    });

    var offer = document.getElementById("draft-offer");
    if (offer) {
      var draft = JSON.parse(document.getElementById("draft-data").textContent);
      var restore = document.getElementById("draft-restore");
      var discard = document.getElementById("draft-discard");
      restore.hidden = discard.hidden = false;
      restore.addEventListener("click", function () {
        if (language) language.value = draft.language;
        if (editor) editor.setValue(draft.source); else textarea.value = draft.source;
        drafted = snapshot();
        offer.remove();
        showDirty();
        say(gettext("Draft restored: not saved yet"), "dirty");
      });
      discard.addEventListener("click", function () {
        var data = new FormData();
        data.set("discard", "1");
        fetch(form.dataset.draftUrl, {
          method: "POST", body: data, credentials: "same-origin",
          headers: { "X-CSRFToken": cookie("csrftoken") },
        });
        offer.remove();
      });
    }

    window.addEventListener("beforeunload", function (event) {
      if (dirty()) { event.preventDefault(); event.returnValue = ""; }
    });

    // -- the robot panel ------------------------------------------------------------------

    var panelBody = document.getElementById("bench-panel-body");
    var toggle = document.getElementById("panel-toggle");
    function loadPanel() {
      if (toggle.getAttribute("aria-expanded") !== "true" || !robotChoice.value) { panelBody.textContent = ""; return; }
      fetch(form.dataset.panelUrl + "?robot=" + encodeURIComponent(robotChoice.value), { credentials: "same-origin" })
        .then(function (response) { return response.ok ? response.text() : ""; })
        .then(function (html) {
          panelBody.innerHTML = html;
          if (window.htmx) window.htmx.process(panelBody);
        });
    }
    toggle.addEventListener("click", function () {
      var open = toggle.getAttribute("aria-expanded") !== "true";
      toggle.setAttribute("aria-expanded", String(open));
      toggle.textContent = open ? gettext("Hide the robot") : gettext("Show the robot");
      document.querySelector(".workbench").classList.toggle("panel-closed", !open);
      loadPanel();
    });
    robotChoice.addEventListener("change", loadPanel);
    // "My sim (new)" ran: the sim made for it is the choice from now on, and its panel shows.
    function mySimMade(name) {
      var chosen = robotChoice.options[robotChoice.selectedIndex];
      if (!name || !chosen || chosen.value !== "+sim") return;
      chosen.value = name;
      chosen.textContent = name + " (" + gettext("my sim") + ")";
      loadPanel();
    }
    loadPanel();
  });
})();
