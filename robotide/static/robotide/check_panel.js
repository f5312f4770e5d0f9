// An exercise's Check on the workbench (templates/classroom/student_workbench.html).
//
// Without scripts the Check button submits the editor's form to the exercise's check URL,
// which saves the text and checks it. With scripts it stays on the page: the workbench saves
// (workbench.js, as its Save), then the check is asked; its answer is the attempt's checklist,
// which follows the attempt (htmx polls it) until it is done.
(function () {
  "use strict";

  document.addEventListener("DOMContentLoaded", function () {
    var button = document.getElementById("check-button");
    var place = document.getElementById("exercise-checklist");
    if (!button || !place) return;
    var state = document.getElementById("check-state");
    var busy = false;

    function say(text, kind) {
      state.textContent = text;
      state.dataset.kind = kind || "";
    }

    function ask() {
      return fetch(button.dataset.checkUrl, {
        method: "POST", credentials: "same-origin", redirect: "manual",
        headers: { "X-CSRFToken": window.robotideCookie("csrftoken"), "X-Requested-With": "fetch" },
      });
    }

    function answered(response) {
      if (response.type === "opaqueredirect" || response.status === 401 || response.status === 403) {
        say(gettext("Not checked: your sign-in has expired. Sign in again, then press Check."), "error");
        return null;
      }
      if (!response.ok) {
        return response.json().then(function (answer) {
          say(answer.error || gettext("Not checked."), "error");
        }, function () {
          say(interpolate(gettext("The server answered %(status)s"), { status: response.status }, true), "error");
        });
      }
      return response.text().then(function (html) {
        place.innerHTML = html;
        if (window.htmx) window.htmx.process(place);
        shown();
      });
    }

    function check(event) {
      event.preventDefault();
      if (busy) return;
      busy = true;
      button.disabled = true;
      say(gettext("Saving…"), "busy");
      var bench = window.robotideWorkbench;
      (bench ? bench.save() : Promise.resolve(true)).then(function (saved) {
        if (!saved) {
          say(gettext("Not checked: the program could not be saved (see above)."), "error");
          return null;
        }
        say(gettext("Starting the check…"), "busy");
        return ask().then(answered);
      }).catch(function () {
        say(gettext("Not sent: the server cannot be reached. Your text is still here."), "error");
      }).finally(function () {
        busy = false;
        button.disabled = false;
      });
    }

    // What the checklist says now, in the status beside the button.
    function shown() {
      var list = place.querySelector(".checklist");
      if (!list) return;
      var done = list.dataset.state === "done" || list.dataset.state === "error";
      if (!done) say(gettext("Checking…"), "busy");
      else if (state.dataset.kind === "busy") say(gettext("Checked"), "saved");
    }

    button.addEventListener("click", check);
    // Polled, the checklist is swapped for a new one: said again once it is done.
    place.addEventListener("htmx:afterSwap", shown);
    new MutationObserver(shown).observe(place, { childList: true });
  });
})();
