// The robot page: driving by hand (buttons, arrow keys, a gamepad) and plots of the readings.
// Commands go over the page's own websocket (htmx's ws extension); the agent stops the robot
// 0.4 s after the last drive command, so each held control repeats its command every 150 ms.
(function () {
  "use strict";

  var REPEAT_MS = 150;
  var DEADZONE = 0.15;
  var socket = null;
  var held = null; // [linear, angular] as fractions of the limits, while a control is held
  var timer = null;

  document.addEventListener("htmx:wsOpen", function (event) {
    socket = event.detail.socketWrapper;
  });
  document.addEventListener("htmx:wsClose", function () {
    socket = null;
  });

  function send(message) {
    if (socket) socket.send(JSON.stringify(message));
  }

  function control() {
    return document.getElementById("control");
  }

  function canDrive() {
    var card = control();
    return card && card.dataset.control !== "other";
  }

  function speed() {
    var input = control() && control().querySelector("input[name=speed]");
    return input ? Number(input.value) / 100 : 0.5;
  }

  function limits() {
    var page = document.querySelector("[data-max-linear]");
    return {
      linear: Number(page && page.dataset.maxLinear) || 0.5,
      angular: Number(page && page.dataset.maxAngular) || 2.0,
    };
  }

  function sendHeld() {
    if (!held) return;
    var max = limits();
    var s = speed();
    send({ drive: [held[0] * max.linear * s, held[1] * max.angular * s] });
  }

  function hold(direction) {
    if (!canDrive()) return;
    var changed = !held || held[0] !== direction[0] || held[1] !== direction[1];
    held = direction;
    if (changed) sendHeld();
    if (!timer) timer = setInterval(sendHeld, REPEAT_MS);
  }

  function letGo() {
    if (!held) return;
    held = null;
    clearInterval(timer);
    timer = null;
    send({ stop: true });
  }

  // -- on-screen buttons --------------------------------------------------------------------

  document.addEventListener("pointerdown", function (event) {
    var button = event.target.closest("#control [data-drive]");
    if (button) {
      event.preventDefault();
      hold(button.dataset.drive.split(",").map(Number));
    } else if (event.target.closest("#control [data-stop]")) {
      letGo();
      send({ stop: true });
    }
  });
  ["pointerup", "pointercancel"].forEach(function (type) {
    document.addEventListener(type, function () {
      if (held && !keys.size && !padActive) letGo();
    });
  });
  document.addEventListener("click", function (event) {
    if (event.target.closest("#control [data-release]")) send({ release: true });
    if (event.target.closest("#control [data-take]")) send({ take: true });
  });

  // -- arrow keys ------------------------------------------------------------------------

  var keys = new Set();
  var ARROWS = { ArrowUp: [1, 0], ArrowDown: [-1, 0], ArrowLeft: [0, 1], ArrowRight: [0, -1] };

  function typing(target) {
    return target.closest("input, textarea, select, [contenteditable]");
  }

  function fromKeys() {
    var linear = 0;
    var angular = 0;
    keys.forEach(function (key) {
      linear += ARROWS[key][0];
      angular += ARROWS[key][1];
    });
    return [Math.max(-1, Math.min(1, linear)), Math.max(-1, Math.min(1, angular))];
  }

  document.addEventListener("keydown", function (event) {
    if (!(event.key in ARROWS) || typing(event.target) || !control()) return;
    event.preventDefault();
    keys.add(event.key);
    hold(fromKeys());
  });
  document.addEventListener("keyup", function (event) {
    if (!keys.delete(event.key)) return;
    if (keys.size) hold(fromKeys());
    else letGo();
  });
  // A hidden page or a lost focus may never see the key being released.
  window.addEventListener("blur", function () {
    keys.clear();
    letGo();
  });
  document.addEventListener("visibilitychange", function () {
    if (document.hidden) {
      keys.clear();
      letGo();
    }
  });

  // -- gamepad: left stick, up = forward, left = turn left ---------------------------------

  var padActive = false;

  function pollPad() {
    var pads = navigator.getGamepads ? navigator.getGamepads() : [];
    var pad = Array.prototype.find.call(pads, function (p) {
      return p && p.connected;
    });
    if (!pad) return;
    var x = pad.axes[0] || 0;
    var y = pad.axes[1] || 0;
    var linear = Math.abs(y) > DEADZONE ? -y : 0;
    var angular = Math.abs(x) > DEADZONE ? -x : 0;
    if (linear || angular) {
      padActive = true;
      hold([linear, angular]);
    } else if (padActive) {
      padActive = false;
      if (!keys.size) letGo();
    }
  }

  window.addEventListener("gamepadconnected", function () {
    if (!window.robotidePadTimer) window.robotidePadTimer = setInterval(pollPad, 100);
  });

  // -- plots of the last minute ----------------------------------------------------------

  var series = {}; // name -> {times: [], values: [], unit, plot}

  function sample() {
    var table = document.getElementById("sensors");
    var box = document.getElementById("plots");
    if (!table || !box || !window.uPlot) return;
    var now = Date.now() / 1000;
    var seconds = Number(box.dataset.seconds) || 60;
    var horizon = now - seconds;
    table.querySelectorAll("tr[data-name]").forEach(function (row) {
      if (row.dataset.value === "") return;
      var name = row.dataset.name;
      if (name === "time") return; // a clock: a straight line
      var entry = series[name] || (series[name] = newSeries(box, name, row.dataset.unit, seconds));
      entry.times.push(now);
      entry.values.push(Number(row.dataset.value));
      while (entry.times.length && entry.times[0] < horizon) {
        entry.times.shift();
        entry.values.shift();
      }
      entry.plot.setData([entry.times, entry.values]);
    });
  }

  function newSeries(box, name, unit, seconds) {
    var empty = box.querySelector(".empty");
    if (empty) empty.remove();
    var figure = document.createElement("figure");
    figure.className = "plot";
    figure.dataset.name = name;
    box.appendChild(figure);
    var plot = new window.uPlot(
      {
        title: name + (unit ? " (" + unit + ")" : ""),
        width: 260,
        height: 110,
        legend: { show: false },
        cursor: { show: false },
        // Always the last minute, however few samples there are yet.
        scales: {
          x: {
            time: true,
            range: function (u, min, max) {
              return [max - seconds, max];
            },
          },
        },
        axes: [{ size: 24, font: "10px system-ui" }, { size: 44, font: "10px system-ui" }],
        series: [{}, { stroke: "#1f5fbf", width: 1.5 }],
      },
      [[], []],
      figure
    );
    return { times: [], values: [], unit: unit, plot: plot };
  }

  document.addEventListener("htmx:wsAfterMessage", function () {
    // The readings table was just swapped in (four times a second at most).
    setTimeout(sample, 0);
  });
})();
