// A simulated robot drawn by the page itself (templates/robots/_simview.html): its world from
// world.json once, then its pose from the robot's websocket, where the agent sends
// {"pose": {x, y, theta, linear, angular, bumper, range, sonar?, t}} up to 20 times a second
// while the robot moves (robots.sim_view). Between two of them the robot is moved along the
// arc of the last one's speeds (as rhal.kinematics.advance_pose), at the display's frame rate;
// each new pose snaps it to where the sim says. Nothing is drawn while the page is hidden, nor
// while the robot stands still and nothing changed. The canvas says what it drew in data-pose
// ("x y theta") and how metres map to its CSS pixels in data-view ("ox oy scale").
(function () {
  "use strict";

  var TRAIL = 600; // poses kept for the path (30 s at 20 a second)
  var HOLD = 0.3; // s: no pose for this long, the robot is drawn where the last one put it
  var MARGIN = 8; // CSS px around the arena
  var COLOURS = {
    outside: "#2b2b2b", floor: "#f6f3ea", grid: "rgba(0,0,0,0.05)", wall: "#5a4a3a",
    box: "#a0764a", boxEdge: "#6e4f2f", robot: "#1f5fbf", nose: "#ffffff", bump: "#d62020",
    beam: "rgba(255,170,0,0.35)", beamEdge: "rgba(200,120,0,0.8)", sonar: "rgba(0,140,120,0.7)",
    trail: "rgba(31,95,191,0.55)", start: "#2e8b57", text: "#333333", zone: "rgba(0,0,0,0.35)",
  };
  var views = new Map(); // canvas -> View

  // -- geometry -------------------------------------------------------------------------------

  // rhal.kinematics.advance_pose: exact along the arc, the chord written with sinc.
  function advance(pose, linear, angular, dt) {
    var half = (angular * dt) / 2;
    var sinc = Math.abs(half) < 1e-4 ? 1 - (half * half) / 6 : Math.sin(half) / half;
    var chord = linear * dt * sinc;
    var mean = pose.theta + half;
    return { x: pose.x + chord * Math.cos(mean), y: pose.y + chord * Math.sin(mean), theta: pose.theta + 2 * half };
  }

  function rotated(cx, cy, w, h, angle) {
    var c = Math.cos(angle || 0), s = Math.sin(angle || 0);
    return [[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]].map(function (p) {
      return [cx + p[0] * c - p[1] * s, cy + p[0] * s + p[1] * c];
    });
  }

  function wallCorners(wall) {
    var dx = wall.to[0] - wall.from[0], dy = wall.to[1] - wall.from[1];
    var length = Math.hypot(dx, dy) || 1e-9;
    var t = (wall.thickness || 0.05) / 2;
    var nx = (-dy / length) * t, ny = (dx / length) * t;
    return [[wall.from[0] + nx, wall.from[1] + ny], [wall.to[0] + nx, wall.to[1] + ny],
      [wall.to[0] - nx, wall.to[1] - ny], [wall.from[0] - nx, wall.from[1] - ny]];
  }

  // -- one canvas -------------------------------------------------------------------------------

  function View(canvas) {
    this.canvas = canvas;
    this.world = null;
    this.robot = { radius: 0.15, range: { cone_deg: 0, max: 4 }, sonar: [] };
    this.speed = 1;
    this.pose = null; // the last pose received, and when (performance.now())
    this.at = 0;
    this.trail = [];
    this.background = null; // the world drawn once per size
    this.dirty = true;
    this.frame = 0;
    var view = this;
    if (window.ResizeObserver) new ResizeObserver(function () { view.resized(); }).observe(canvas);
    this.load();
  }

  View.prototype.load = function () {
    var view = this;
    if (this.loading) return;
    this.loading = true;
    var asked = performance.now();
    fetch(this.canvas.dataset.worldUrl, { credentials: "same-origin", headers: { Accept: "application/json" } })
      .then(function (response) {
        return response.json().then(function (answer) {
          if (!response.ok) throw new Error(answer.error || response.status);
          return answer;
        });
      })
      .then(function (answer) {
        view.world = answer.world;
        view.robot = answer.robot || view.robot;
        view.speed = Number(answer.speed) || 1;
        view.error = "";
        if (answer.pose && (!view.pose || view.at < asked)) view.received(answer.pose);
        var size = view.world.size;
        view.canvas.style.aspectRatio = size.width + " / " + size.height;
        view.canvas.style.setProperty("--simview-ratio", size.width / size.height);
        view.resized();
      })
      .catch(function (error) {
        view.error = String(error.message || error);
        view.dirty = true;
        view.wake();
      })
      .finally(function () { view.loading = false; });
  };

  View.prototype.resized = function () {
    var ratio = window.devicePixelRatio || 1;
    var width = this.canvas.clientWidth, height = this.canvas.clientHeight;
    if (!width || !height) return;
    this.canvas.width = Math.round(width * ratio);
    this.canvas.height = Math.round(height * ratio);
    this.ratio = ratio;
    this.background = null;
    this.dirty = true;
    this.wake();
  };

  // A pose from the websocket (or world.json's): a jump (a reset, a teleport) clears the path.
  View.prototype.received = function (pose) {
    var now = performance.now();
    var last = this.pose;
    if (last) {
      var dt = (now - this.at) / 1000;
      var reach = 0.2 + Math.abs(last.linear || 0) * this.speed * Math.min(dt, HOLD) * 2;
      var backwards = typeof pose.t === "number" && typeof last.t === "number" && pose.t < last.t;
      if (backwards || Math.hypot(pose.x - last.x, pose.y - last.y) > reach) this.trail = [];
    }
    this.pose = pose;
    this.at = now;
    this.trail.push([pose.x, pose.y]);
    if (this.trail.length > TRAIL) this.trail.splice(0, this.trail.length - TRAIL);
    this.dirty = true;
    this.wake();
  };

  View.prototype.moving = function () {
    var p = this.pose;
    return p && (p.linear || p.angular) && (performance.now() - this.at) / 1000 < HOLD + 0.05;
  };

  View.prototype.wake = function () {
    var view = this;
    if (this.frame || document.hidden) return;
    this.frame = requestAnimationFrame(function () { view.frame = 0; view.draw(); });
  };

  // Where the robot is now: the last pose moved along its arc for the time since it came.
  View.prototype.now = function () {
    var p = this.pose;
    var dt = Math.min((performance.now() - this.at) / 1000, HOLD) * this.speed;
    if (!p.linear && !p.angular) return { x: p.x, y: p.y, theta: p.theta };
    return advance(p, p.linear, p.angular, dt);
  };

  View.prototype.mapping = function () {
    var width = this.canvas.width / this.ratio, height = this.canvas.height / this.ratio;
    var size = this.world.size;
    var scale = Math.max(1e-3, Math.min((width - 2 * MARGIN) / size.width, (height - 2 * MARGIN) / size.height));
    return { ox: width / 2, oy: height / 2, scale: scale, width: width, height: height };
  };

  View.prototype.draw = function () {
    var canvas = this.canvas;
    var ctx = canvas.getContext("2d");
    if (!this.ratio) this.resized();
    if (!this.ratio) return;
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    if (!this.world) {
      ctx.fillStyle = COLOURS.outside;
      ctx.fillRect(0, 0, canvas.width, canvas.height);
      if (this.error) {
        ctx.fillStyle = "#ffffff";
        ctx.font = "13px system-ui, sans-serif";
        ctx.fillText(this.error, 10, 22, canvas.width / this.ratio - 20);
      }
      return;
    }
    var m = this.mapping();
    canvas.dataset.view = [m.ox, m.oy, m.scale].map(function (v) { return v.toFixed(3); }).join(" ");
    if (!this.background) this.background = this.drawWorld(m);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(this.background, 0, 0);
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    if (this.pose) {
      var pose = this.now();
      this.drawTrail(ctx, m, pose);
      this.drawSensors(ctx, m, pose);
      this.drawRobot(ctx, m, pose);
      canvas.dataset.pose = [pose.x, pose.y, pose.theta].map(function (v) { return v.toFixed(3); }).join(" ");
    }
    this.dirty = false;
    if (this.moving()) this.wake();
  };

  // -- the world, drawn once per size ---------------------------------------------------------

  View.prototype.drawWorld = function (m) {
    var layer = document.createElement("canvas");
    layer.width = this.canvas.width;
    layer.height = this.canvas.height;
    var ctx = layer.getContext("2d");
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    var w = this.world, s = m.scale;
    function X(x) { return m.ox + x * s; }
    function Y(y) { return m.oy - y * s; }
    function polygon(points) {
      ctx.beginPath();
      points.forEach(function (p, i) { if (i) ctx.lineTo(X(p[0]), Y(p[1])); else ctx.moveTo(X(p[0]), Y(p[1])); });
      ctx.closePath();
    }
    var hw = w.size.width / 2, hh = w.size.height / 2;
    var font = Math.max(9, Math.min(13, 0.12 * s));
    ctx.fillStyle = COLOURS.outside;
    ctx.fillRect(0, 0, m.width, m.height);
    ctx.fillStyle = COLOURS.floor;
    ctx.fillRect(X(-hw), Y(hh), w.size.width * s, w.size.height * s);
    // A 1 m grid, faint: distances can be read off the floor.
    ctx.strokeStyle = COLOURS.grid;
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (var gx = Math.ceil(-hw); gx <= hw; gx++) { ctx.moveTo(X(gx), Y(-hh)); ctx.lineTo(X(gx), Y(hh)); }
    for (var gy = Math.ceil(-hh); gy <= hh; gy++) { ctx.moveTo(X(-hw), Y(gy)); ctx.lineTo(X(hw), Y(gy)); }
    ctx.stroke();
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    (w.zones || []).forEach(function (zone) {
      var corners = rotated(zone.x, zone.y, zone.width, zone.height, 0);
      polygon(corners);
      if (zone.colour) {
        ctx.globalAlpha = 0.55;
        ctx.fillStyle = zone.colour;
        ctx.fill();
        ctx.globalAlpha = 1;
      }
      ctx.setLineDash([4, 3]);
      ctx.strokeStyle = COLOURS.zone;
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = COLOURS.text;
      ctx.font = "italic " + font + "px system-ui, sans-serif";
      ctx.fillText(zone.name, X(zone.x), Y(zone.y), zone.width * s);
    });
    (w.lines || []).forEach(function (line) {
      ctx.strokeStyle = line.colour || "#000000";
      ctx.lineWidth = Math.max(1, (line.width || 0.03) * s);
      ctx.lineJoin = ctx.lineCap = "round";
      ctx.beginPath();
      line.points.forEach(function (p, i) { if (i) ctx.lineTo(X(p[0]), Y(p[1])); else ctx.moveTo(X(p[0]), Y(p[1])); });
      ctx.stroke();
    });
    (w.start || []).slice(0, 1).forEach(function (start) {
      startMarker(ctx, X(start.x), Y(start.y), start.theta, (this.robot.radius || 0.15) * s);
    }, this);
    (w.boxes || []).forEach(function (box) {
      polygon(rotated(box.x, box.y, box.width, box.height, box.angle));
      ctx.fillStyle = COLOURS.box;
      ctx.fill();
      ctx.strokeStyle = COLOURS.boxEdge;
      ctx.lineWidth = 1.5;
      ctx.stroke();
    });
    (w.walls || []).forEach(function (wall) {
      polygon(wallCorners(wall));
      ctx.fillStyle = COLOURS.wall;
      ctx.fill();
    });
    // The outer walls: just outside the floor.
    ctx.strokeStyle = COLOURS.wall;
    ctx.lineWidth = 4;
    ctx.strokeRect(X(-hw) - 2, Y(hh) - 2, w.size.width * s + 4, w.size.height * s + 4);
    // A zone named after its landmark (the built-in worlds' are) says the name once.
    var zoneNames = new Set((w.zones || []).map(function (zone) { return zone.name; }));
    (w.landmarks || []).forEach(function (mark) {
      var size = Math.max(6, (mark.size || 0.4) * s);
      ctx.save();
      ctx.translate(X(mark.x), Y(mark.y));
      ctx.rotate(-mark.facing);
      // Seen from above, a code on a wall is a thin plate; its text beside it, into the room.
      ctx.fillStyle = "#111111";
      ctx.fillRect(-2, -size / 2, 4, size);
      ctx.restore();
      if (zoneNames.has(mark.text)) return;
      ctx.fillStyle = COLOURS.text;
      ctx.font = "bold " + font + "px system-ui, sans-serif";
      // Clear of its wall whichever way it faces: half the label's extent that way, and a gap.
      var c = Math.cos(mark.facing), n = Math.sin(mark.facing);
      var into = (Math.abs(c) * ctx.measureText(mark.text).width + Math.abs(n) * font) / 2 + 5;
      ctx.fillText(mark.text, X(mark.x) + c * into, Y(mark.y) - n * into);
    });
    return layer;
  };

  // -- what moves, drawn each frame -----------------------------------------------------------

  View.prototype.drawTrail = function (ctx, m, pose) {
    if (this.trail.length < 1) return;
    ctx.strokeStyle = COLOURS.trail;
    ctx.lineWidth = 2;
    ctx.lineJoin = ctx.lineCap = "round";
    ctx.beginPath();
    this.trail.forEach(function (p, i) {
      var x = m.ox + p[0] * m.scale, y = m.oy - p[1] * m.scale;
      if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y);
    });
    ctx.lineTo(m.ox + pose.x * m.scale, m.oy - pose.y * m.scale);
    ctx.stroke();
  };

  View.prototype.drawSensors = function (ctx, m, pose) {
    var p = this.pose, s = m.scale;
    var x = m.ox + pose.x * s, y = m.oy - pose.y * s;
    var spec = this.robot.range || {};
    if (typeof p.range === "number") {
      var half = ((spec.cone_deg || 0) * Math.PI) / 360;
      var length = p.range * s;
      ctx.beginPath();
      if (half > 0) {
        ctx.moveTo(x, y);
        ctx.arc(x, y, length, -pose.theta - half, -pose.theta + half);
        ctx.closePath();
        ctx.fillStyle = COLOURS.beam;
        ctx.fill();
      } else {
        ctx.moveTo(x, y);
        ctx.lineTo(x + Math.cos(pose.theta) * length, y - Math.sin(pose.theta) * length);
      }
      ctx.strokeStyle = COLOURS.beamEdge;
      ctx.lineWidth = 1;
      ctx.stroke();
    }
    var angles = this.robot.sonar || [];
    if (Array.isArray(p.sonar) && angles.length) {
      ctx.strokeStyle = COLOURS.sonar;
      ctx.lineWidth = 1;
      ctx.beginPath();
      angles.forEach(function (degrees, i) {
        var reading = p.sonar[i];
        if (typeof reading !== "number") return;
        var a = pose.theta + (degrees * Math.PI) / 180;
        ctx.moveTo(x, y);
        ctx.lineTo(x + Math.cos(a) * reading * s, y - Math.sin(a) * reading * s);
      });
      ctx.stroke();
    }
  };

  View.prototype.drawRobot = function (ctx, m, pose) {
    var r = Math.max(3, (this.robot.radius || 0.15) * m.scale);
    var x = m.ox + pose.x * m.scale, y = m.oy - pose.y * m.scale;
    ctx.save();
    ctx.translate(x, y);
    ctx.rotate(-pose.theta);
    ctx.beginPath();
    ctx.arc(0, 0, r, 0, 2 * Math.PI);
    ctx.fillStyle = COLOURS.robot;
    ctx.fill();
    ctx.lineWidth = this.pose.bumper ? Math.max(3, r * 0.25) : 1.5;
    ctx.strokeStyle = this.pose.bumper ? COLOURS.bump : "#0c2d5e";
    ctx.stroke();
    // Its nose: which way it faces, clear of the centre (where data-pose says it is).
    ctx.beginPath();
    ctx.moveTo(r * 0.85, 0);
    ctx.lineTo(r * 0.4, r * 0.35);
    ctx.lineTo(r * 0.4, -r * 0.35);
    ctx.closePath();
    ctx.fillStyle = COLOURS.nose;
    ctx.fill();
    ctx.restore();
  };

  // A start pose: a dashed circle of the robot's size (r, px) with an arrow its heading.
  function startMarker(ctx, x, y, theta, r) {
    ctx.save();
    ctx.translate(x, y);
    ctx.rotate(-theta);
    ctx.strokeStyle = COLOURS.start;
    ctx.lineWidth = 1.5;
    ctx.setLineDash([3, 3]);
    ctx.beginPath();
    ctx.arc(0, 0, r, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.moveTo(r * 0.9, 0);
    ctx.lineTo(r * 0.2, r * 0.45);
    ctx.lineTo(r * 0.2, -r * 0.45);
    ctx.closePath();
    ctx.stroke();
    ctx.restore();
  }

  // A world drawn as here, for pages that draw it without a live robot (replay.js): a layer of
  // the canvas' size; m: {ox, oy, scale, width, height} (CSS px, as View.mapping).
  window.robotideSimview = {
    startMarker: startMarker,
    drawWorld: function (canvas, ratio, world, robot, m) {
      return View.prototype.drawWorld.call({ canvas: canvas, ratio: ratio, world: world, robot: robot }, m);
    },
  };

  // -- wiring ---------------------------------------------------------------------------------

  function viewOf(canvas) {
    var view = views.get(canvas);
    if (!view) {
      view = new View(canvas);
      views.set(canvas, view);
    }
    return view;
  }

  function scan(root) {
    (root || document).querySelectorAll("canvas.simview-canvas").forEach(viewOf);
    views.forEach(function (view, canvas) { if (!canvas.isConnected) views.delete(canvas); });
  }

  // The pose frames are JSON, not HTML for htmx to swap: taken here, before htmx sees them.
  document.addEventListener("htmx:wsBeforeMessage", function (event) {
    var text = event.detail.message;
    if (typeof text !== "string" || text.charAt(0) !== "{") return;
    var message;
    try { message = JSON.parse(text); } catch (e) { return; }
    if (!message || !message.pose) return;
    event.preventDefault();
    event.target.querySelectorAll("canvas.simview-canvas").forEach(function (canvas) {
      viewOf(canvas).received(message.pose);
    });
  });
  // A socket (re)opened: the robot may have moved, or been given another world, meanwhile.
  document.addEventListener("htmx:wsOpen", function (event) {
    scan(event.target);
    event.target.querySelectorAll("canvas.simview-canvas").forEach(function (canvas) {
      var view = viewOf(canvas);
      if (view.world || view.error) view.load();
    });
  });
  document.addEventListener("htmx:load", function (event) { scan(event.target.parentNode || document); });
  document.addEventListener("visibilitychange", function () {
    views.forEach(function (view) {
      if (document.hidden) {
        if (view.frame) cancelAnimationFrame(view.frame);
        view.frame = 0;
      } else {
        view.wake();
      }
    });
  });
  window.addEventListener("resize", function () { views.forEach(function (view) { view.resized(); }); });
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", function () { scan(); });
  else scan();
})();
