// A run's status line and page: the running time counts up each second; error lines that come
// live become links to the program's line, as the server renders those it had. Without this
// file the page works still: the time as rendered (the page refreshes), links as rendered.
(function () {
  "use strict";

  // As the server's duration filter writes it, to the second: 4 s, 3 min 04 s, 2 h 05 min.
  function shown(seconds) {
    var whole = Math.floor(seconds);
    if (whole < 60) return whole + " s";
    var minutes = Math.floor(whole / 60);
    if (minutes < 60) return minutes + " min " + String(whole % 60).padStart(2, "0") + " s";
    return Math.floor(minutes / 60) + " h " + String(minutes % 60).padStart(2, "0") + " min";
  }

  // A clock (robotide's running_clock filter) counts from the server's reading when it was
  // rendered plus the time this page has seen pass since: a browser's clock set wrong does
  // not matter. A status replaced (the run ended) takes its clock with it: that one stops.
  var seen = new WeakMap();
  function tick() {
    document.querySelectorAll(".clock[data-started-ms]").forEach(function (clock) {
      if (!seen.has(clock)) {
        var elapsed = Number(clock.dataset.nowMs) - Number(clock.dataset.startedMs);
        seen.set(clock, { elapsed: elapsed, at: performance.now() });
      }
      var base = seen.get(clock);
      var text = shown((base.elapsed + performance.now() - base.at) / 1000);
      if (clock.textContent !== text) clock.textContent = text;
    });
  }

  // Only the run page's log: the workbench's console makes its own (it marks the editor).
  function linkErrorLines() {
    document.querySelectorAll("#log.run-log .ln[data-line]").forEach(function (line) {
      if (line.querySelector("a")) return;
      var target = "line-" + line.dataset.line;
      if (!document.getElementById(target)) return;
      var link = document.createElement("a");
      link.href = "#" + target;
      link.append.apply(link, Array.prototype.slice.call(line.childNodes));
      line.append(link);
    });
  }

  document.addEventListener("DOMContentLoaded", function () {
    tick();
    setInterval(tick, 250);  // a second's change shown within a quarter of one
  });
  document.addEventListener("htmx:wsAfterMessage", linkErrorLines);
})();
