// Worlds drawn without a live robot: an exercise's world with its start poses, and an
// attempt's replays (templates/classroom/student_exercise.html, attempt_body.html).
//
// A canvas.replay-canvas takes its drawing from a JSON script element (data-replay-data: its
// id) or a URL (data-replay-src: /attempts/<id>/replay/<variant>.json): {world, robot, starts?,
// start?, poses?: [[t, x, y, theta]], contacts?: [[t, x, y]], said?, output?, end?}. The world
// is drawn as the live sim view draws it (simview.js). A replay's controls beside it (a range
// input and a play button) move the robot along its path; the canvas says in data-t the time
// it shows and in data-pose where the robot is ("x y theta").
(function () {
  "use strict";

  var MARGIN = 8; // CSS px around the arena, as simview.js
  var PLAY_SECONDS = 15; // a whole run plays in at most this long (and no slower than real time)
  var COLOURS = {
    start: "#2e8b57", path: "rgba(31,95,191,0.35)", done: "rgba(31,95,191,0.9)",
    robot: "#1f5fbf", edge: "#0c2d5e", nose: "#ffffff", contact: "#d62020", said: "#8a3ffc",
    label: "#123d21",
  };
  var replays = new Map(); // canvas -> Replay

  function Replay(canvas) {
    this.canvas = canvas;
    this.data = null;
    this.t = 0;
    this.end = 0;
    this.playing = false;
    this.figure = canvas.closest("figure") || canvas.parentNode;
    this.scrub = this.figure.querySelector(".replay-scrub");
    this.play = this.figure.querySelector(".replay-play");
    this.time = this.figure.querySelector(".replay-time");
    this.note = this.figure.querySelector(".replay-note");
    var replay = this;
    if (window.ResizeObserver) new ResizeObserver(function () { replay.resized(); }).observe(canvas);
    this.load();
  }

  Replay.prototype.load = function () {
    var replay = this, canvas = this.canvas;
    var inline = canvas.dataset.replayData && document.getElementById(canvas.dataset.replayData);
    var loaded = inline
      ? Promise.resolve(JSON.parse(inline.textContent))
      : fetch(canvas.dataset.replaySrc, { credentials: "same-origin", headers: { Accept: "application/json" } })
        .then(function (response) {
          return response.json().then(function (answer) {
            if (!response.ok) throw new Error(answer.error || response.status);
            return answer;
          });
        });
    loaded.then(function (data) {
      replay.data = data;
      var poses = data.poses || [];
      replay.end = poses.length ? poses[poses.length - 1][0] : 0;
      if (data.end && typeof data.end.t === "number") replay.end = Math.max(replay.end, data.end.t);
      replay.t = replay.end; // the whole path first
      var size = data.world.size;
      canvas.style.aspectRatio = size.width + " / " + size.height;
      canvas.style.setProperty("--replay-ratio", size.width / size.height);
      replay.wire();
      replay.resized();
    }).catch(function (error) {
      replay.error = String(error.message || error);
      if (replay.note) replay.note.textContent = replay.error;
      canvas.dataset.error = replay.error;
    });
  };

  Replay.prototype.wire = function () {
    var replay = this;
    if (!this.scrub) return;
    var poses = this.data.poses || [];
    this.scrub.disabled = this.play.disabled = poses.length < 2;
    this.scrub.value = this.scrub.max;
    this.scrub.addEventListener("input", function () {
      replay.stop();
      replay.t = (Number(replay.scrub.value) / Number(replay.scrub.max)) * replay.end;
      replay.draw();
    });
    this.play.addEventListener("click", function () {
      if (replay.playing) replay.stop(); else replay.start();
    });
    this.play.textContent = "▶";
    this.play.setAttribute("aria-label", gettext("Play"));
  };

  Replay.prototype.start = function () {
    var replay = this;
    if (this.t >= this.end) this.t = 0;
    this.playing = true;
    this.play.textContent = "❚❚";
    this.play.setAttribute("aria-label", gettext("Pause"));
    var rate = Math.max(1, this.end / PLAY_SECONDS);
    var last = performance.now();
    function step(now) {
      if (!replay.playing) return;
      replay.t = Math.min(replay.end, replay.t + ((now - last) / 1000) * rate);
      last = now;
      replay.scrub.value = replay.end ? Math.round((replay.t / replay.end) * Number(replay.scrub.max)) : 0;
      replay.draw();
      if (replay.t >= replay.end) replay.stop();
      else replay.frame = requestAnimationFrame(step);
    }
    this.frame = requestAnimationFrame(step);
  };

  Replay.prototype.stop = function () {
    this.playing = false;
    if (this.frame) cancelAnimationFrame(this.frame);
    this.frame = 0;
    if (this.play) {
      this.play.textContent = "▶";
      this.play.setAttribute("aria-label", gettext("Play"));
    }
  };

  Replay.prototype.resized = function () {
    var ratio = window.devicePixelRatio || 1;
    var width = this.canvas.clientWidth, height = this.canvas.clientHeight;
    if (!width || !height || !this.data) return;
    this.canvas.width = Math.round(width * ratio);
    this.canvas.height = Math.round(height * ratio);
    this.ratio = ratio;
    this.background = null;
    this.draw();
  };

  Replay.prototype.mapping = function () {
    var width = this.canvas.width / this.ratio, height = this.canvas.height / this.ratio;
    var size = this.data.world.size;
    var scale = Math.max(1e-3, Math.min((width - 2 * MARGIN) / size.width, (height - 2 * MARGIN) / size.height));
    return { ox: width / 2, oy: height / 2, scale: scale, width: width, height: height };
  };

  // Where the robot was at time t: between the two poses around it.
  Replay.prototype.poseAt = function (t) {
    var poses = this.data.poses || [];
    if (!poses.length) {
      var s = this.data.start;
      return s ? { x: s.x, y: s.y, theta: s.theta, index: 0 } : null;
    }
    var lo = 0, hi = poses.length - 1;
    if (t <= poses[0][0]) return { x: poses[0][1], y: poses[0][2], theta: poses[0][3], index: 0 };
    if (t >= poses[hi][0]) return { x: poses[hi][1], y: poses[hi][2], theta: poses[hi][3], index: hi };
    while (hi - lo > 1) {
      var mid = (lo + hi) >> 1;
      if (poses[mid][0] <= t) lo = mid; else hi = mid;
    }
    var a = poses[lo], b = poses[hi];
    var f = b[0] > a[0] ? (t - a[0]) / (b[0] - a[0]) : 0;
    var turn = Math.atan2(Math.sin(b[3] - a[3]), Math.cos(b[3] - a[3]));
    return { x: a[1] + (b[1] - a[1]) * f, y: a[2] + (b[2] - a[2]) * f, theta: a[3] + turn * f, index: lo };
  };

  Replay.prototype.draw = function () {
    if (!this.data || !this.ratio) return;
    var canvas = this.canvas, ctx = canvas.getContext("2d"), data = this.data;
    var m = this.mapping(), s = m.scale;
    var radius = (data.robot && data.robot.radius) || data.radius || 0.15;
    if (!this.background) {
      this.background = window.robotideSimview.drawWorld(canvas, this.ratio, data.world, data.robot || {}, m);
    }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(this.background, 0, 0);
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    function X(x) { return m.ox + x * s; }
    function Y(y) { return m.oy - y * s; }
    (data.starts || []).forEach(function (start) { drawStart(ctx, X(start.x), Y(start.y), start.theta, radius * s, start.label); });
    if (data.start) drawStart(ctx, X(data.start.x), Y(data.start.y), data.start.theta, radius * s, "");
    var poses = data.poses || [];
    if (!poses.length) {
      if (this.note && data.end) this.note.textContent = gettext("No path was recorded: the program did not move the robot.");
      return;
    }
    var now = this.poseAt(this.t);
    // The whole path faint, the part already driven strong.
    ctx.lineJoin = ctx.lineCap = "round";
    ctx.lineWidth = 2;
    ctx.strokeStyle = COLOURS.path;
    ctx.beginPath();
    poses.forEach(function (p, i) { if (i) ctx.lineTo(X(p[1]), Y(p[2])); else ctx.moveTo(X(p[1]), Y(p[2])); });
    ctx.stroke();
    ctx.strokeStyle = COLOURS.done;
    ctx.lineWidth = 2.5;
    ctx.beginPath();
    for (var i = 0; i <= now.index; i++) { if (i) ctx.lineTo(X(poses[i][1]), Y(poses[i][2])); else ctx.moveTo(X(poses[i][1]), Y(poses[i][2])); }
    ctx.lineTo(X(now.x), Y(now.y));
    ctx.stroke();
    // What it printed or said: a dot where it was then.
    var replay = this, t = this.t;
    (data.said || []).concat(data.output || []).forEach(function (event) {
      if (event[0] > t) return;
      var at = replay.poseAt(event[0]);
      ctx.fillStyle = COLOURS.said;
      ctx.beginPath();
      ctx.arc(X(at.x), Y(at.y), 3, 0, 2 * Math.PI);
      ctx.fill();
    });
    // Contacts: a red ring where each began (all of them, faint ahead of the time shown).
    (data.contacts || []).forEach(function (c) {
      ctx.globalAlpha = c[0] <= t ? 1 : 0.35;
      ctx.strokeStyle = COLOURS.contact;
      ctx.lineWidth = 2.5;
      var r = Math.max(5, radius * s * 0.6);
      ctx.beginPath();
      ctx.moveTo(X(c[1]) - r, Y(c[2]) - r); ctx.lineTo(X(c[1]) + r, Y(c[2]) + r);
      ctx.moveTo(X(c[1]) + r, Y(c[2]) - r); ctx.lineTo(X(c[1]) - r, Y(c[2]) + r);
      ctx.stroke();
      ctx.globalAlpha = 1;
    });
    var touching = (data.contacts || []).some(function (c) { return c[0] <= t && t - c[0] < 0.3; });
    drawRobot(ctx, X(now.x), Y(now.y), now.theta, Math.max(3, radius * s), touching);
    canvas.dataset.t = this.t.toFixed(2);
    canvas.dataset.pose = [now.x, now.y, now.theta].map(function (v) { return v.toFixed(3); }).join(" ");
    this.say(t);
  };

  // The time shown, and the last thing printed or said by then.
  Replay.prototype.say = function (t) {
    if (this.time) {
      this.time.textContent = interpolate(gettext("%(t)s s of %(end)s s"), { t: t.toFixed(1), end: this.end.toFixed(1) }, true);
      if (this.scrub) this.scrub.setAttribute("aria-valuetext", this.time.textContent);
    }
    if (!this.note) return;
    var data = this.data, last = null, kind = "";
    (data.said || []).forEach(function (e) { if (e[0] <= t && (!last || e[0] >= last[0])) { last = e; kind = "said"; } });
    (data.output || []).forEach(function (e) { if (e[0] <= t && (!last || e[0] > last[0])) { last = e; kind = "output"; } });
    var contacts = (data.contacts || []).filter(function (c) { return c[0] <= t; }).length;
    var parts = [];
    if (last) {
      parts.push(interpolate(kind === "said" ? gettext("said at %(t)s s: %(text)s") : gettext("printed at %(t)s s: %(text)s"),
        { t: Number(last[0]).toFixed(1), text: String(last[1]).slice(0, 200) }, true));
    }
    if (contacts) parts.push(interpolate(ngettext("%(n)s contact so far", "%(n)s contacts so far", contacts), { n: contacts }, true));
    this.note.textContent = parts.join(" · ");
  };

  function drawStart(ctx, x, y, theta, r, label) {
    window.robotideSimview.startMarker(ctx, x, y, theta, r);
    if (label) {
      ctx.font = "bold 12px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      ctx.fillStyle = COLOURS.label;
      ctx.fillText(label, x + r + 7, y - r - 4);
    }
  }

  function drawRobot(ctx, x, y, theta, r, touching) {
    ctx.save();
    ctx.translate(x, y);
    ctx.rotate(-theta);
    ctx.beginPath();
    ctx.arc(0, 0, r, 0, 2 * Math.PI);
    ctx.fillStyle = COLOURS.robot;
    ctx.fill();
    ctx.lineWidth = touching ? Math.max(3, r * 0.25) : 1.5;
    ctx.strokeStyle = touching ? COLOURS.contact : COLOURS.edge;
    ctx.stroke();
    ctx.beginPath();
    ctx.moveTo(r * 0.85, 0);
    ctx.lineTo(r * 0.4, r * 0.35);
    ctx.lineTo(r * 0.4, -r * 0.35);
    ctx.closePath();
    ctx.fillStyle = COLOURS.nose;
    ctx.fill();
    ctx.restore();
  }

  function scan(root) {
    (root || document).querySelectorAll("canvas.replay-canvas").forEach(function (canvas) {
      if (!replays.has(canvas)) replays.set(canvas, new Replay(canvas));
    });
    replays.forEach(function (replay, canvas) { if (!canvas.isConnected) { replay.stop(); replays.delete(canvas); } });
  }

  // The attempt page's body is swapped in when the attempt is done (htmx): its replays then.
  document.addEventListener("htmx:load", function (event) { scan(event.target.parentNode || document); });
  window.addEventListener("resize", function () { replays.forEach(function (replay) { replay.resized(); }); });
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", function () { scan(); });
  else scan();
})();
