// The exercise editor (templates/classroom/exercise_edit.html): the form works without this
// script (its add and remove buttons post it, and the page comes back changed); with it, rows
// are added and removed in the page, a check shows only its kind's fields, and the world is
// drawn: a click on the map adds a start pose there, a drag from it sets the heading.
//
// The page's data (json_script "exercise-editor-data"): the chosen world's document (or null),
// the built-in worlds' names, and where a world's document is read: /worlds/<id>.json for a
// stored one, /worlds/builtin/<name>.json for a built-in one (as their export gives them).
// The map's coordinates are the world's (metres, y north); the SVG's y is flipped (svg y = -y).
(function () {
  "use strict";

  var SVG_NS = "http://www.w3.org/2000/svg";
  var ROBOT_RADIUS = 0.15; // m, as drawn: the default robot's
  var SNAP = 0.05; // m: where a click puts a pose
  var NOTCH = 15; // degrees: a dragged heading's step
  var DRAG = 0.12; // m: a press moved less than this is a click (the heading stays 90°)

  document.addEventListener("DOMContentLoaded", function () {
    var source = document.getElementById("exercise-editor-data");
    var form = document.getElementById("ex-form");
    if (source && form) start(JSON.parse(source.textContent), form);
  });

  function start(data, form) {
    form.classList.add("ex-js");
    var variants = document.getElementById("ex-variants");
    var checks = document.getElementById("ex-checks");
    var worldSelect = document.getElementById("ex-world");
    var map = document.getElementById("ex-map");
    var mapState = document.getElementById("ex-map-state");
    var newHidden = document.getElementById("ex-new-hidden");
    var zoneList = document.getElementById("ex-zone-names");
    var world = data.world;
    var loading = 0;
    // What was typed and not saved yet (a refused page's too): leaving the page asks first.
    var dirty = !!document.getElementById("ex-errors");
    function touched() { dirty = true; }
    form.addEventListener("input", touched);
    form.addEventListener("change", touched);
    form.addEventListener("submit", function () { dirty = false; });
    window.addEventListener("beforeunload", function (event) { if (dirty) event.preventDefault(); });

    // -- rows ---------------------------------------------------------------------------------

    function nextIndex(list) {
      var most = -1;
      list.querySelectorAll(":scope > li[data-index]").forEach(function (li) {
        most = Math.max(most, Number(li.dataset.index));
      });
      return most + 1;
    }

    function addRow(kind) {
      var list = kind === "variant" ? variants : checks;
      var template = document.getElementById("ex-" + kind + "-template");
      var index = String(nextIndex(list));
      var holder = document.createElement("div");
      holder.innerHTML = template.innerHTML.split("__i__").join(index);
      var row = holder.querySelector("li");
      list.appendChild(row);
      renumber(list);
      touched();
      if (kind === "check") {
        showKindFields(row);
        var none = document.getElementById("ex-no-checks");
        if (none) none.hidden = true;
      }
      return row;
    }

    function renumber(list) {
      list.querySelectorAll(":scope > li").forEach(function (li, i) {
        var n = li.querySelector(".ex-n");
        if (n) n.textContent = String(i + 1);
      });
    }

    function showKindFields(row) {
      var kind = row.querySelector("select.ex-kind").value;
      row.querySelectorAll(".ex-kind-field, .ex-kind-help").forEach(function (field) {
        var kinds = (field.dataset.kinds || "").split(" ");
        field.toggleAttribute("data-off", kinds.indexOf(kind) < 0);
      });
    }

    form.addEventListener("click", function (event) {
      var button = event.target.closest("button");
      if (!button || !form.contains(button)) return;
      var action = button.value || "";
      if (button.dataset.add) {
        event.preventDefault();
        var row = addRow(button.dataset.add);
        var first = row.querySelector("input[type=text], select");
        if (first) first.focus();
        if (button.dataset.add === "variant") draw();
      } else if (action.indexOf("remove-variant-") === 0 || action.indexOf("remove-check-") === 0) {
        event.preventDefault();
        var li = button.closest("li");
        var list = li.parentNode;
        var next = li.nextElementSibling || li.previousElementSibling;
        li.remove();
        renumber(list);
        touched();
        // Focus stays in the list (or goes to its add button): not lost to the page's top.
        var target = next ? next.querySelector("input, select") : form.querySelector("[data-add=" + (list === variants ? "variant" : "check") + "]");
        if (target) target.focus();
        draw();
      }
    });

    form.addEventListener("change", function (event) {
      if (event.target.matches("select.ex-kind")) showKindFields(event.target.closest("li"));
      if (event.target === worldSelect) loadWorld(worldSelect.value);
      if (event.target.closest("#ex-variants")) {
        var li = event.target.closest("li");
        if (li) li.classList.toggle("is-hidden", li.querySelector("[data-field=hidden]").checked);
        draw();
      }
    });
    form.addEventListener("input", function (event) {
      if (event.target.closest("#ex-variants")) draw();
    });
    checks.querySelectorAll(":scope > li").forEach(showKindFields);

    // -- the world ----------------------------------------------------------------------------

    function worldUrl(value) {
      if (data.builtin.indexOf(value) >= 0) return data.builtin_url.replace("NAME", encodeURIComponent(value));
      return data.world_url.replace(/0\.json$/, encodeURIComponent(value) + ".json");
    }

    function loadWorld(value) {
      var ticket = ++loading;
      say(gettext("Loading the world…"));
      fetch(worldUrl(value), { credentials: "same-origin", headers: { Accept: "application/json" } })
        .then(function (response) {
          if (!response.ok) throw new Error(String(response.status));
          return response.json();
        })
        .then(function (doc) {
          if (ticket !== loading) return;
          world = doc;
          zoneNames();
          say("");
          draw();
        })
        .catch(function () {
          if (ticket !== loading) return;
          world = null;
          draw();
          say(gettext("This world could not be loaded: the start poses are still saved, and checked when saved."));
        });
    }

    function zoneNames() {
      while (zoneList.firstChild) zoneList.removeChild(zoneList.firstChild);
      ((world && world.zones) || []).forEach(function (zone) {
        var option = document.createElement("option");
        option.value = zone.name;
        zoneList.appendChild(option);
      });
    }

    function say(text) { mapState.textContent = text; }

    // -- the map ------------------------------------------------------------------------------

    function el(name, attrs, parent) {
      var node = document.createElementNS(SVG_NS, name);
      for (var key in attrs) if (attrs[key] !== undefined && attrs[key] !== null) node.setAttribute(key, attrs[key]);
      if (parent) parent.appendChild(node);
      return node;
    }

    function rotated(cx, cy, w, h, angle) {
      var c = Math.cos(angle || 0), s = Math.sin(angle || 0);
      return [[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]].map(function (p) {
        return [cx + p[0] * c - p[1] * s, -(cy + p[0] * s + p[1] * c)].join(",");
      }).join(" ");
    }

    function num(text) {
      var value = Number(String(text || "").replace(",", "."));
      return text !== "" && isFinite(value) ? value : null;
    }

    function poses() {
      var list = [];
      variants.querySelectorAll(":scope > li").forEach(function (li, i) {
        var x = num(li.querySelector("[data-field=x]").value);
        var y = num(li.querySelector("[data-field=y]").value);
        var deg = num(li.querySelector("[data-field=theta_deg]").value);
        if (x === null || y === null) return;
        list.push({ n: i + 1, x: x, y: y, theta: ((deg || 0) * Math.PI) / 180, hidden: li.querySelector("[data-field=hidden]").checked, row: li });
      });
      return list;
    }

    var ghost = null; // the pose being placed: {x, y, theta}

    function draw() {
      if (!map) return;
      while (map.firstChild) map.removeChild(map.firstChild);
      if (!world || !world.size) {
        map.setAttribute("viewBox", "-2 -2 4 4");
        return;
      }
      var w = world.size.width, h = world.size.height, m = 0.15;
      map.setAttribute("viewBox", [-w / 2 - m, -h / 2 - m, w + 2 * m, h + 2 * m].join(" "));
      map.style.setProperty("--ex-ratio", String((w + 2 * m) / (h + 2 * m)));
      el("rect", { x: -w / 2, y: -h / 2, width: w, height: h, class: "ex-floor" }, map);
      var grid = el("g", { class: "ex-grid" }, map);
      for (var gx = Math.ceil(-w / 2); gx <= w / 2; gx++) el("line", { x1: gx, x2: gx, y1: -h / 2, y2: h / 2 }, grid);
      for (var gy = Math.ceil(-h / 2); gy <= h / 2; gy++) el("line", { x1: -w / 2, x2: w / 2, y1: -gy, y2: -gy }, grid);
      var font = Math.max(0.1, Math.min(0.18, w / 30));
      (world.zones || []).forEach(function (zone) {
        el("rect", { x: zone.x - zone.width / 2, y: -zone.y - zone.height / 2, width: zone.width, height: zone.height, class: "ex-zone", fill: zone.colour || "#ffffff" }, map);
        var label = el("text", { x: zone.x, y: -zone.y, class: "ex-zone-name", "font-size": font }, map);
        label.textContent = zone.name;
      });
      (world.lines || []).forEach(function (line) {
        el("polyline", { points: line.points.map(function (p) { return p[0] + "," + -p[1]; }).join(" "), class: "ex-line", stroke: line.colour || "#000000", "stroke-width": line.width || 0.03 }, map);
      });
      (world.boxes || []).forEach(function (box) {
        el("polygon", { points: rotated(box.x, box.y, box.width, box.height, box.angle), class: "ex-box" }, map);
      });
      (world.walls || []).forEach(function (wall) {
        el("line", { x1: wall.from[0], y1: -wall.from[1], x2: wall.to[0], y2: -wall.to[1], class: "ex-wall", "stroke-width": wall.thickness || 0.05 }, map);
      });
      (world.landmarks || []).forEach(function (mark) {
        var size = mark.size || 0.4, c = Math.cos(mark.facing || 0), s = Math.sin(mark.facing || 0);
        el("line", { x1: mark.x + s * size / 2, y1: -(mark.y - c * size / 2), x2: mark.x - s * size / 2, y2: -(mark.y + c * size / 2), class: "ex-landmark" }, map);
      });
      el("rect", { x: -w / 2, y: -h / 2, width: w, height: h, class: "ex-arena" }, map);
      poses().forEach(function (pose) { drawPose(pose, false); });
      if (ghost) drawPose(ghost, true);
    }

    function drawPose(pose, isGhost) {
      var g = el("g", { class: "ex-pose" + (pose.hidden ? " hidden" : "") + (isGhost ? " ghost" : ""), "data-n": pose.n || "" }, map);
      var r = ROBOT_RADIUS;
      el("circle", { cx: pose.x, cy: -pose.y, r: r, class: "ex-pose-body" }, g);
      el("line", { x1: pose.x, y1: -pose.y, x2: pose.x + Math.cos(pose.theta) * r * 1.6, y2: -(pose.y + Math.sin(pose.theta) * r * 1.6), class: "ex-pose-heading" }, g);
      if (pose.n) {
        var label = el("text", { x: pose.x, y: -pose.y, class: "ex-pose-n", "font-size": r * 1.1 }, g);
        label.textContent = String(pose.n);
      }
    }

    function point(event) {
      var p = new DOMPoint(event.clientX, event.clientY).matrixTransform(map.getScreenCTM().inverse());
      return { x: p.x, y: -p.y };
    }

    function snap(v) { return Math.round(Math.round(v / SNAP) * SNAP * 1000) / 1000; }

    function inside(p) {
      return world && world.size && Math.abs(p.x) <= world.size.width / 2 && Math.abs(p.y) <= world.size.height / 2;
    }

    // A press on a start pose drags it (a click on it goes to its row); elsewhere it places
    // a new one.
    var press = null;
    var moving = null; // {row, from: {x, y}, at: {x, y}, moved}
    function poseAt(p) {
      var found = null;
      poses().forEach(function (pose) {
        if (Math.hypot(pose.x - p.x, pose.y - p.y) <= ROBOT_RADIUS * 1.2) found = pose;
      });
      return found;
    }
    map.addEventListener("pointerdown", function (event) {
      if (!world || event.button > 0) return;
      var p = point(event);
      if (!inside(p)) return;
      event.preventDefault();
      map.setPointerCapture(event.pointerId);
      var hit = poseAt(p);
      if (hit) {
        moving = { row: hit.row, n: hit.n, at: p, moved: false };
        return;
      }
      press = { x: snap(p.x), y: snap(p.y) };
      ghost = { x: press.x, y: press.y, theta: Math.PI / 2, hidden: newHidden.checked };
      draw();
    });
    map.addEventListener("pointermove", function (event) {
      if (moving) {
        var q = point(event);
        if (!moving.moved && Math.hypot(q.x - moving.at.x, q.y - moving.at.y) < DRAG / 2) return;
        moving.moved = true;
        if (!inside(q)) return;
        moving.row.querySelector("[data-field=x]").value = String(snap(q.x));
        moving.row.querySelector("[data-field=y]").value = String(snap(q.y));
        touched();
        draw();
        return;
      }
      if (!press) return;
      var p = point(event);
      var dx = p.x - press.x, dy = p.y - press.y;
      if (Math.hypot(dx, dy) < DRAG) return;
      var deg = Math.round((Math.atan2(dy, dx) * 180) / Math.PI / NOTCH) * NOTCH;
      ghost.theta = (deg * Math.PI) / 180;
      draw();
    });
    function release(event, keep) {
      if (moving) {
        var row = moving.row, n = moving.n, moved = moving.moved;
        moving = null;
        if (map.hasPointerCapture(event.pointerId)) map.releasePointerCapture(event.pointerId);
        if (!moved) {
          row.querySelector("[data-field=x]").focus();
        } else {
          say(interpolate(gettext("Start pose %(n)s moved to x %(x)s m, y %(y)s m."), {
            n: n, x: row.querySelector("[data-field=x]").value, y: row.querySelector("[data-field=y]").value }, true));
        }
        draw();
        return;
      }
      if (!press) return;
      var pose = ghost;
      press = null;
      ghost = null;
      if (map.hasPointerCapture(event.pointerId)) map.releasePointerCapture(event.pointerId);
      if (keep) place(pose);
      draw();
    }
    map.addEventListener("pointerup", function (event) { release(event, true); });
    map.addEventListener("pointercancel", function (event) { release(event, false); });

    function place(pose) {
      var row = addRow("variant");
      var deg = Math.round((pose.theta * 180) / Math.PI);
      if (deg > 180) deg -= 360;
      row.querySelector("[data-field=x]").value = String(pose.x);
      row.querySelector("[data-field=y]").value = String(pose.y);
      row.querySelector("[data-field=theta_deg]").value = String(deg);
      var hidden = row.querySelector("[data-field=hidden]");
      hidden.checked = !!pose.hidden;
      row.classList.toggle("is-hidden", hidden.checked);
      var n = variants.querySelectorAll(":scope > li").length;
      say(interpolate(pose.hidden ? gettext("Hidden start pose %(n)s added at x %(x)s m, y %(y)s m, heading %(deg)s°.")
        : gettext("Start pose %(n)s added at x %(x)s m, y %(y)s m, heading %(deg)s°."), { n: n, x: pose.x, y: pose.y, deg: deg }, true));
    }

    document.querySelector(".ex-map-box").hidden = false;
    // Refused: the first field named in the errors is where the teacher goes on.
    if (document.getElementById("ex-errors")) {
      var invalid = form.querySelector("[aria-invalid=true]");
      if (invalid) {
        invalid.focus({ preventScroll: true });
        invalid.scrollIntoView({ block: "center" });
      }
    }
    zoneNames();
    draw();
    if (!world && worldSelect.value) loadWorld(worldSelect.value);
  }
})();
