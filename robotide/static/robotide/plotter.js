// The workbench plotter: the numbers a run prints and shows, plotted live (uPlot), as
// Arduino's serial plotter and Thonny's plotter do, for any language.
//
// What it reads (templates/programs/_plotter.html says the same to the user):
// - the program's stdout lines in the console (#log-lines .ln.o, not stderr nor robotide's own
//   lines): `name: value` / `name=value` pairs, several to a line, else a line of nothing but
//   numbers separated by commas, spaces or tabs (series "value 1", "value 2"… as Arduino IDE 2
//   names them); any other line is left out;
// - the numbers the run shows (bot.show): the robot panel's cards (robots/_shows.html), sampled
//   each time the robot's readings arrive (about four times a second), series "show: name".
// The lines carry no time: x is when a line reached this page, in seconds since the run appeared
// in the console (the browser's clock). A batch of lines arriving together shares one time.
// Caps, so a program printing fast cannot freeze the page: at most data-max-series series,
// data-max-points points (the oldest dropped, which the UI says), redraws at most one per
// animation frame and MIN_GAP_MS apart. Program text only ever goes in as text (textContent,
// uPlot's labels): never as HTML.
(function () {
  "use strict";

  var MIN_GAP_MS = 50;
  var MAX_LINE = 1000;  // characters of a line read: a long line cannot make the parsing slow
  var MAX_NAME = 40;
  var CHART_HEIGHT = 240;
  // Distinct on white, the first ten Tableau's; the plots of a robot's readings use #1f5fbf.
  var COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
    "#7f7f7f", "#bcbd22", "#17becf", "#0b3d91", "#a50f15", "#006d2c", "#b35806", "#54278f",
    "#543005", "#ae017e", "#252525", "#707000", "#01665e"];

  var NUMBER = "[-+]?(?:\\d+(?:\\.\\d*)?|\\.\\d+)(?:e[-+]?\\d+)?|[-+]?(?:nan|inf(?:inity)?)";
  var NAME_CHARS = "[\\p{L}\\p{N}_.\\-\\[\\]]";
  // A name (words joined by single spaces, starting with a letter), maybe quoted as a dict or
  // JSON prints it, then ":" or "=", then a number ending there (not "0.5s", not "3abc").
  var PAIR = new RegExp("([\\p{L}_]" + NAME_CHARS + "*(?: " + NAME_CHARS + "+)*)[\"']?\\s*[:=]\\s*(" +
    NUMBER + ")(?![\\p{L}\\p{N}_]|\\.\\d)", "giu");
  var BARE = new RegExp("^(?:" + NUMBER + ")$", "i");
  var FIELDS = /[,\t ]+/;

  function number(text) {
    var value = Number(text);
    return isFinite(value) ? value : null;  // nan, inf: a gap in the line
  }

  // A line's [name, value] pairs: its named values, else its columns, else none.
  function parseLine(line, columnName) {
    line = line.slice(0, MAX_LINE);
    var pairs = [];
    var match;
    PAIR.lastIndex = 0;
    while ((match = PAIR.exec(line)) !== null) pairs.push([match[1].slice(0, MAX_NAME), number(match[2])]);
    if (pairs.length) return pairs;
    var fields = line.trim().split(FIELDS).filter(Boolean);
    if (!fields.length || !fields.every(function (field) { return BARE.test(field); })) return [];
    return fields.map(function (field, i) { return [columnName(i + 1), number(field)]; });
  }

  function format(template, values) {
    return template.replace(/%\((\w+)\)s/g, function (all, key) { return key in values ? values[key] : all; });
  }

  // Numbers as the page's language writes them (1,5 in pt-BR); the CSV keeps Python's 1.5.
  var language = document.documentElement.lang || undefined;
  var secondsFormat = new Intl.NumberFormat(language, { minimumFractionDigits: 2, maximumFractionDigits: 2 });
  var valueFormat = new Intl.NumberFormat(language, { maximumFractionDigits: 3 });

  function seconds(value) { return value == null ? "—" : secondsFormat.format(value); }

  function shortNumber(value) {
    if (value == null) return "—";
    var abs = Math.abs(value);
    return abs !== 0 && (abs >= 1e6 || abs < 1e-3) ? value.toExponential(3) : valueFormat.format(value);
  }

  document.addEventListener("DOMContentLoaded", function () {
    var section = document.getElementById("plotter");
    var consoleBox = document.getElementById("console");
    if (!section || !consoleBox || !window.uPlot) return;
    var words = section.dataset;
    var maxPoints, maxSeries, windowSeconds;  // read at each run's start (limits())
    var chartBox = document.getElementById("plotter-chart");
    var pauseButton = document.getElementById("plotter-pause");
    var scroll = document.getElementById("plotter-scroll");
    var summary = document.getElementById("plotter-summary");
    var viewNote = document.getElementById("plotter-view");
    var droppedNote = document.getElementById("plotter-dropped");
    var tooManyNote = document.getElementById("plotter-too-many");

    function columnName(n) { return format(words.valueName, {n: n}); }

    // -- what is recorded: one row per line or sample, one column per series --------------

    var run = null;  // the run plotted (its id, as the console has it)
    var startedAt = 0;  // performance.now() when the run appeared
    var times = [];
    var names = [];
    // name -> values (null where a row has none), as long as times. No prototype: a program
    // may well print "constructor: 3".
    var columns = Object.create(null);
    var linesRead = 0;  // of the run's #log-lines

    function reset() {
      times = [];
      names = [];
      columns = Object.create(null);
      droppedNote.hidden = tooManyNote.hidden = true;
      follow(true);
      rebuild();
    }

    function limits() {
      maxPoints = Number(words.maxPoints) || 20000;
      maxSeries = Number(words.maxSeries) || 20;
      windowSeconds = Number(words.window) || 30;
    }

    function newRun(id) {
      limits();
      run = id;
      startedAt = performance.now();
      linesRead = 0;
      reset();
      section.hidden = true;  // until this run gives a number
    }

    function record(pairs) {
      var row = Object.create(null);
      var added = false;
      pairs.forEach(function (pair) {
        var name = pair[0];
        if (!(name in columns)) {
          if (names.length >= maxSeries) { tooManyNote.hidden = false; return; }
          names.push(name);
          columns[name] = times.map(function () { return null; });
          added = true;
        }
        row[name] = pair[1];
      });
      if (!Object.keys(row).length) return;
      times.push((performance.now() - startedAt) / 1000);
      names.forEach(function (name) { columns[name].push(name in row ? row[name] : null); });
      dropOldest();
      if (section.hidden) section.hidden = false;
      if (added) rebuild(); else drawSoon();
    }

    // The oldest tenth goes at once: a splice per row would cost as much as the row.
    function dropOldest() {
      if (times.length <= maxPoints + maxPoints / 10) return;
      var cut = times.length - maxPoints;
      times.splice(0, cut);
      names.forEach(function (name) { columns[name].splice(0, cut); });
      droppedNote.hidden = false;
    }

    // -- reading the console and the robot panel ------------------------------------------

    var busyMs = 0;  // time spent reading lines and drawing (robotidePlotter.busy)

    function readConsole() {
      var began = performance.now();
      readLines();
      busyMs += performance.now() - began;
    }

    function readLines() {
      var place = consoleBox.querySelector("#console-run[data-run]");
      if (!place) return;
      if (place.dataset.run !== run) newRun(place.dataset.run);
      var lines = place.querySelector("#log-lines");
      if (!lines) return;
      // The lines arrive appended; a #log-lines sent again (a socket reconnecting) holds the
      // same lines first: those already read are not read twice.
      var children = lines.children;
      for (; linesRead < children.length; linesRead++) {
        var line = children[linesRead];
        if (!line.classList.contains("o")) continue;
        var pairs = parseLine(line.textContent, columnName);
        if (pairs.length) record(pairs);
      }
    }

    function runOngoing() {
      var status = consoleBox.querySelector("#console-run #run-status");
      return status && ["queued", "starting", "running"].indexOf(status.dataset.state) >= 0;
    }

    function sampleShows() {
      if (!run || !runOngoing()) return;
      var pairs = [];
      document.querySelectorAll("#bench-panel #shows figure.show[data-run]").forEach(function (card) {
        if (card.dataset.run !== run || card.hasAttribute("data-ended") || card.dataset.value === "") return;
        pairs.push([words.showPrefix + " " + card.dataset.name.slice(0, MAX_NAME), Number(card.dataset.value)]);
      });
      if (pairs.length) record(pairs);
    }

    new MutationObserver(readConsole).observe(consoleBox, { childList: true, subtree: true });
    document.addEventListener("htmx:wsAfterMessage", function (event) {
      // The robot panel's readings (and any shown values with them) were just swapped in.
      var message = event.detail && event.detail.message;
      if (typeof message !== "string" || message.indexOf('id="sensors"') < 0) return;
      if (event.target.closest && event.target.closest("#bench-panel")) setTimeout(sampleShows, 0);
    });

    // -- the chart ------------------------------------------------------------------------

    var chart = null;
    var following = true;
    var frozen = null;  // {min, max} of the view while not following
    var pending = false;
    var lastDraw = 0;
    var draws = 0;

    function data(copy) {
      var all = [times].concat(names.map(function (name) { return columns[name]; }));
      return copy ? all.map(function (values) { return values.slice(); }) : all;
    }

    function rebuild() {
      if (chart) { chart.destroy(); chart = null; }
      if (!names.length) { summary.textContent = viewNote.textContent = ""; return; }
      var series = [{ label: words.timeLegend, value: function (u, v) { return seconds(v); } }];
      names.forEach(function (name, i) {
        series.push({ label: name, stroke: COLORS[i % COLORS.length], width: 1.5, spanGaps: true,
          value: function (u, v) { return shortNumber(v); } });
      });
      chart = new window.uPlot({
        width: chartWidth(), height: CHART_HEIGHT,
        scales: { x: { time: false } },
        axes: [{ label: words.timeLabel, labelSize: 20, size: 36 }, { size: 56 }],
        series: series,
        cursor: { drag: { x: true, y: false, setScale: false } },
        hooks: { setSelect: [zoomed] },
      }, data(!following), chartBox);
      var canvas = chart.root.querySelector("canvas");
      canvas.setAttribute("role", "img");
      canvas.setAttribute("aria-label", chartBox.dataset.label);
      canvas.setAttribute("aria-describedby", "plotter-summary");
      chart.over.addEventListener("mouseleave", function () { setTimeout(latestInLegend, 0); });
      draw(true);
    }

    function chartWidth() { return Math.max(200, chartBox.clientWidth || section.clientWidth || 300); }

    function followedView() {
      var last = times.length ? times[times.length - 1] : 0;
      var min = Math.max(0, last - windowSeconds);  // from the run's start while it is short
      return { min: min, max: Math.max(last, min + 0.5) };
    }

    function drawSoon() {
      if (pending) return;
      pending = true;
      var wait = Math.max(0, lastDraw + MIN_GAP_MS - performance.now());
      setTimeout(function () { requestAnimationFrame(function () { pending = false; draw(false); }); }, wait);
    }

    // Following: the newest values, each redraw. Not following: the view stays as it was
    // (new values are recorded, not drawn) until the user moves it.
    function draw(moved) {
      var began = lastDraw = performance.now();
      if (chart && (following || moved)) {
        var view = following ? followedView() : frozen;
        chart.batch(function () {
          chart.setData(data(!following), false);
          chart.setScale("x", { min: view.min, max: view.max });
        });
        draws++;
        describe(view);
        latestInLegend();
      }
      scrollMatches();
      busyMs += performance.now() - began;
    }

    // With the pointer off the chart, its legend says the newest values (uPlot's says none).
    function latestInLegend() {
      if (chart && chart.cursor.left < 0 && chart.data[0].length) chart.setLegend({ idx: chart.data[0].length - 1 });
    }

    function describe(view) {
      var last = times.length - 1;
      var latest = names.map(function (name) {
        for (var i = last; i >= 0; i--) if (columns[name][i] != null) return name + " " + shortNumber(columns[name][i]);
        return name + " —";
      });
      summary.textContent = format(words.latest, { time: seconds(times[last]), values: latest.join(", ") }) + " " +
        format(words.counts, { points: times.length });
      viewNote.textContent = format(words.scrolled, { from: seconds(view.min), to: seconds(view.max) });
    }

    function zoomed(u) {
      var select = u.select;
      if (select.width < 2) return;
      var min = u.posToVal(select.left, "x");
      var max = u.posToVal(select.left + select.width, "x");
      u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
      freeze({ min: min, max: max });
    }

    function freeze(view) {
      frozen = view;
      follow(false);
      draw(true);
    }

    function follow(on) {
      following = on;
      if (on) frozen = null;
      pauseButton.setAttribute("aria-pressed", String(!on));
      pauseButton.textContent = on ? words.pause : words.resume;
      if (on && chart) draw(true);
    }

    // -- the controls ---------------------------------------------------------------------

    // The slider says where the view's right end is in the history: its end is the newest.
    function scrollMatches() {
      if (following) { scroll.value = scroll.max; return; }
      var span = historySpan();
      if (frozen && span.length > 0) scroll.value = Math.round((frozen.max - span.first) / span.length * scroll.max);
    }

    function historySpan() {
      var first = times.length ? times[0] : 0;
      return { first: first, length: (times.length ? times[times.length - 1] : 0) - first };
    }

    scroll.addEventListener("input", function () {
      if (Number(scroll.value) >= Number(scroll.max)) { follow(true); return; }
      var span = historySpan();
      var width = frozen ? frozen.max - frozen.min : windowSeconds;
      var max = span.first + span.length * Number(scroll.value) / Number(scroll.max);
      var min = Math.max(span.first, max - width);
      freeze({ min: min, max: Math.max(max, min + 0.5) });
    });

    pauseButton.addEventListener("click", function () {
      if (following) freeze(chart ? { min: chart.scales.x.min, max: chart.scales.x.max } : followedView());
      else follow(true);
    });

    document.getElementById("plotter-clear").addEventListener("click", function () {
      reset();
    });

    document.getElementById("plotter-csv").addEventListener("click", function () {
      var blob = new Blob([csv()], { type: "text/csv;charset=utf-8" });
      var link = document.createElement("a");
      link.href = URL.createObjectURL(blob);
      link.download = words.fileName + "-run-" + run + "-plot.csv";
      document.body.appendChild(link);
      link.click();
      link.remove();
      setTimeout(function () { URL.revokeObjectURL(link.href); }, 10000);
    });

    function csvField(text) {
      return /[",\r\n]/.test(text) ? '"' + text.replace(/"/g, '""') + '"' : text;
    }

    function csv() {
      var rows = [[words.timeColumn].concat(names).map(csvField).join(",")];
      times.forEach(function (time, i) {
        rows.push([time.toFixed(3)].concat(names.map(function (name) {
          var value = columns[name][i];
          return value == null ? "" : String(value);
        })).join(","));
      });
      return rows.join("\r\n") + "\r\n";
    }

    if (window.ResizeObserver) {
      new ResizeObserver(function () {
        if (chart && chartWidth() !== chart.width) { chart.setSize({ width: chartWidth(), height: CHART_HEIGHT }); }
      }).observe(chartBox);
    }

    // For tests and the curious: what is recorded and what is drawn.
    window.robotidePlotter = {
      parse: function (line) { return parseLine(line, columnName); },
      run: function () { return run; },
      series: function () { return names.slice(); },
      values: function (name) { return (columns[name] || []).filter(function (v) { return v != null; }); },
      points: function () { return times.length; },
      following: function () { return following; },
      draws: function () { return draws; },
      busy: function () { return busyMs; },
      colors: COLORS.slice(),
      view: function () {
        return chart && { min: chart.scales.x.min, max: chart.scales.x.max, drawn: chart.data[0].length };
      },
    };
    limits();
    readConsole();
  });
})();
