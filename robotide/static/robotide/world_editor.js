// The world editor (templates/worlds/editor.html): a teacher draws a sim's world on an SVG.
//
// The page's data (json_script "world-editor-data") is the world's document (the JSON of
// rhal.simulator.world, format 1), its id (null: not saved yet) and whether this user may
// change it. Every change edits that document and redraws it; undo and redo step through
// snapshots of it. Saving sends it to the worlds API, which validates it: an error names an
// item by its path ("walls[2].to"), which is selected and shown with the message beside it.
//
// Coordinates: the document's (metres, x east, y north, origin at the arena's centre); the
// SVG's user units are metres too, with y flipped (svg y = -y), so no transform is needed.
(function () {
  "use strict";

  var SVG_NS = "http://www.w3.org/2000/svg";
  var KINDS = ["zones", "lines", "walls", "boxes", "landmarks", "start"];  // drawing order
  var TOOL_KIND = { wall: "walls", box: "boxes", zone: "zones", line: "lines", landmark: "landmarks", start: "start" };
  var HISTORY_MAX = 200;
  var MIN_SIZE = 0.05;  // m: a shorter wall or a smaller box drawn is a slip of the finger
  var LINE_STEP = 0.05;  // m between a drawn line's points without the grid
  var ZONE_COLOUR = "#ffe08a";
  var DEG = 180 / Math.PI;

  document.addEventListener("DOMContentLoaded", function () {
    var source = document.getElementById("world-editor-data");
    if (source) start(JSON.parse(source.textContent));
  });

  function start(data) {
    var svg = document.getElementById("we-canvas");
    var form = document.getElementById("we-form");
    var stateNote = document.getElementById("we-state");
    var hint = document.getElementById("we-hint");
    var snapBox = document.getElementById("we-snap");
    var gridInput = document.getElementById("we-grid");
    var saveButton = document.getElementById("we-save");
    var copyButton = document.getElementById("we-copy");
    var undoButton = document.getElementById("we-undo");
    var redoButton = document.getElementById("we-redo");
    var deleteButton = document.getElementById("we-delete");
    var toolButtons = Array.prototype.slice.call(document.querySelectorAll("[data-tool]"));

    var doc = normalised(data.world);
    var worldId = data.id;
    var canEdit = !!data.can_edit;
    var tool = "select";
    var selected = null;  // {kind, index}
    var error = null;  // {kind, index, field, message}: the server's last refusal
    var drag = null;  // what the pointer is doing between down and up
    var draft = null;  // {kind, item}: the item being drawn
    var history = [JSON.stringify(doc)];
    var at = 0;  // history[at] is the document as it is
    var savedText = history[0];
    var busy = false;
    var frame = 0;

    document.querySelector(".world-editor").hidden = false;

    // -- the document ---------------------------------------------------------------------

    function list(kind) { return doc[kind]; }
    function item(sel) { return sel && doc[sel.kind][sel.index]; }

    // Records the document as it is now: one undo step (nothing if it did not change).
    function commit() {
      var text = JSON.stringify(doc);
      if (text === history[at]) return;
      history.length = at + 1;
      history.push(text);
      if (history.length > HISTORY_MAX) history.shift();
      at = history.length - 1;
      error = null;
      changed();
    }

    function restore(step) {
      var to = at + step;
      if (to < 0 || to >= history.length) return;
      at = to;
      doc = JSON.parse(history[at]);
      if (selected && !item(selected)) selected = null;
      error = null;
      changed();
      buildForm();
    }

    function changed() {
      undoButton.disabled = at === 0;
      redoButton.disabled = at === history.length - 1;
      deleteButton.disabled = !canEdit || !selected;
      if (history[at] !== savedText) say(gettext("Unsaved changes"), "dirty");
      else if (stateNote.dataset.kind === "dirty") say(gettext("Saved"), "saved");
      render();
    }

    function say(message, kind) {
      stateNote.textContent = message;
      stateNote.dataset.kind = kind || "";
    }

    // -- the grid -------------------------------------------------------------------------

    function step() {
      var value = Number(gridInput.value);
      return value > 0 ? value : 0.1;
    }
    function snapping() { return snapBox.checked; }
    function round(v) { return Math.round(v * 1000) / 1000; }
    function snap(v) { return snapping() ? round(Math.round(v / step()) * step()) : round(v); }
    function snapPoint(p) { return [snap(p[0]), snap(p[1])]; }
    function snapAngle(a) {
      var notch = Math.PI / 12;  // 15°
      return snapping() ? Math.round(a / notch) * notch : a;
    }

    // -- drawing --------------------------------------------------------------------------

    function margin() { return Math.max(0.4, 0.08 * Math.max(doc.size.width, doc.size.height)); }

    function el(name, attrs, parent) {
      var node = document.createElementNS(SVG_NS, name);
      for (var key in attrs) if (attrs[key] !== undefined && attrs[key] !== null) node.setAttribute(key, attrs[key]);
      if (parent) parent.appendChild(node);
      return node;
    }

    function render() {
      if (frame) return;
      frame = requestAnimationFrame(function () { frame = 0; draw(); });
    }

    var pixel = 0.01;  // m a screen pixel spans, as last drawn

    // The zoom: 1 shows the whole arena; more, a part of it around `centre` (SVG units).
    var zoom = 1, centre = [0, 0], ZOOM_MAX = 20;

    function viewBox() {
      var w = doc.size.width + 2 * margin(), h = doc.size.height + 2 * margin();
      if (zoom <= 1) return [-w / 2, -h / 2, w, h];
      var vw = w / zoom, vh = h / zoom;
      // The centre stays where the view is within the arena's drawing.
      centre = [Math.max(-w / 2 + vw / 2, Math.min(w / 2 - vw / 2, centre[0])), Math.max(-h / 2 + vh / 2, Math.min(h / 2 - vh / 2, centre[1]))];
      return [centre[0] - vw / 2, centre[1] - vh / 2, vw, vh];
    }

    // Zooms by `factor` keeping the SVG point `at` (default: the view's centre) where it is.
    function zoomBy(factor, at) {
      var before = zoom, box = viewBox();
      at = at || [box[0] + box[2] / 2, box[1] + box[3] / 2];
      zoom = Math.max(1, Math.min(ZOOM_MAX, zoom * factor));
      centre = [at[0] + (box[0] + box[2] / 2 - at[0]) * before / zoom, at[1] + (box[1] + box[3] / 2 - at[1]) * before / zoom];
      render();
    }

    function draw() {
      var w = doc.size.width, h = doc.size.height, m = margin(), box = viewBox();
      pixel = box[2] / (svg.clientWidth || 600);
      svg.setAttribute("viewBox", box.map(round).join(" "));
      svg.classList.toggle("zoomed", zoom > 1);
      // Its shape is the arena's: CSS keeps it within the screen's height by this ratio.
      svg.style.setProperty("--we-ratio", String((w + 2 * m) / (h + 2 * m)));
      while (svg.firstChild) svg.removeChild(svg.firstChild);
      el("rect", { x: -w / 2, y: -h / 2, width: w, height: h, class: "we-floor" }, svg);
      drawGrid(w, h);
      KINDS.forEach(function (kind) {
        var layer = el("g", { class: "we-layer we-" + kind }, svg);
        list(kind).forEach(function (it, index) { drawItem(layer, kind, it, index); });
      });
      el("rect", { x: -w / 2, y: -h / 2, width: w, height: h, class: "we-arena" }, svg);
      if (draft) drawItem(el("g", { class: "we-draft" }, svg), draft.kind, draft.item, -1);
      if (selected && canEdit && tool === "select") drawHandles();
      svg.setAttribute("aria-label", describe());
    }

    function drawGrid(w, h) {
      var g = el("g", { class: "we-grid" }, svg);
      var minor = step();
      if (!snapping() || Math.max(w, h) / minor > 250) minor = 1;
      // Never thousands of lines (an arena typed far too large, refused when saved).
      while (Math.max(w, h) / minor > 250) minor *= 10;
      function lines(size, other, vertical) {
        for (var i = Math.ceil(-size / 2 / minor); i * minor <= size / 2 + 1e-9; i++) {
          var v = round(i * minor);
          var major = Math.abs(v - Math.round(v)) < 1e-9;
          el("line", vertical ? { x1: v, x2: v, y1: -other / 2, y2: other / 2 } : { x1: -other / 2, x2: other / 2, y1: -v, y2: -v },
            g).setAttribute("class", major ? "major" : "minor");
        }
      }
      lines(w, h, true);
      lines(h, w, false);
    }

    function drawItem(layer, kind, it, index) {
      var g = el("g", { "data-kind": kind, "data-index": index }, layer);
      var classes = ["we-item"];
      if (selected && selected.kind === kind && selected.index === index) classes.push("selected");
      if (error && error.kind === kind && error.index === index) classes.push("invalid");
      g.setAttribute("class", classes.join(" "));
      DRAW[kind](g, it, index);
    }

    var DRAW = {
      walls: function (g, wall) {
        var a = wall.from, b = wall.to;
        var ends = { x1: a[0], y1: -a[1], x2: b[0], y2: -b[1] };
        el("line", Object.assign({ class: "we-hit" }, ends), g);
        el("line", Object.assign({ class: "we-wall", "stroke-width": Math.max(wall.thickness || 0.05, 3 * pixel) }, ends), g);
      },
      boxes: function (g, box) {
        el("rect", {
          x: box.x - box.width / 2, y: -box.y - box.height / 2, width: box.width, height: box.height,
          class: "we-box", transform: box.angle ? "rotate(" + round(-box.angle * DEG) + " " + box.x + " " + -box.y + ")" : null,
        }, g);
      },
      zones: function (g, zone) {
        el("rect", {
          x: zone.x - zone.width / 2, y: -zone.y - zone.height / 2, width: zone.width, height: zone.height,
          class: "we-zone" + (zone.colour ? "" : " unpainted"), fill: zone.colour || null,
        }, g);
        // Its name in a corner, clear of what stands in its middle: a top one, unless the zone
        // is in the arena's north part, where the landmark it is named after may be.
        var size = Math.min(0.12, zone.height / 2), inset = 0.03 + size / 2;
        var north = zone.y > 0 && Math.abs(zone.y) >= Math.abs(zone.x);
        var y = north ? zone.y - zone.height / 2 + inset : zone.y + zone.height / 2 - inset;
        label(g, zone.name, zone.x - zone.width / 2 + 0.04, y, size, "we-zone-name");
      },
      lines: function (g, line) {
        var points = line.points.map(function (p) { return p[0] + "," + -p[1]; }).join(" ");
        el("polyline", { points: points, class: "we-hit" }, g);
        el("polyline", { points: points, class: "we-line", stroke: line.colour || "#000000", "stroke-width": line.width || 0.03 }, g);
      },
      landmarks: function (g, mark) {
        var along = [-Math.sin(mark.facing), Math.cos(mark.facing)], half = (mark.size || 0.4) / 2;
        var a = [mark.x - along[0] * half, mark.y - along[1] * half], b = [mark.x + along[0] * half, mark.y + along[1] * half];
        el("line", { x1: a[0], y1: -a[1], x2: b[0], y2: -b[1], class: "we-hit" }, g);
        el("line", { x1: a[0], y1: -a[1], x2: b[0], y2: -b[1], class: "we-landmark" }, g);
        // Its text as a sign on the wall reads: along the wall, just in front of it, upright.
        var tx = mark.x + Math.cos(mark.facing) * 0.09, ty = mark.y + Math.sin(mark.facing) * 0.09;
        var along = Math.round(mark.facing * DEG + 90);
        along = ((along + 90) % 180 + 180) % 180 - 90;
        label(g, mark.text, tx, ty, 0.1, "we-landmark-text").setAttribute("transform", "rotate(" + -along + " " + tx + " " + -ty + ")");
      },
      start: function (g, pose, index) {
        var r = robotRadius();
        var c = Math.cos(pose.theta), s = Math.sin(pose.theta);
        el("circle", { cx: pose.x, cy: -pose.y, r: r, class: "we-start" + (index === 0 ? " first" : "") }, g);
        el("line", { x1: pose.x + c * r, y1: -(pose.y + s * r), x2: pose.x + c * r * 1.6, y2: -(pose.y + s * r * 1.6), class: "we-heading" }, g);
        if (index >= 0) label(g, String(index + 1), pose.x, pose.y, r, "we-start-number");
      },
    };

    function label(g, text, x, y, size, cls) {
      var t = el("text", { x: x, y: -y, "font-size": round(Math.max(size, 11 * pixel)), class: cls }, g);  // readable on a phone
      t.textContent = text || "";
      return t;
    }

    function robotRadius() { return (doc.robot && doc.robot.radius) || 0.15; }

    // Handles of the selected item: what a drag changes other than moving it whole.
    function drawHandles() {
      var it = item(selected);
      var g = el("g", { class: "we-handles" }, svg);
      handles(selected.kind, it).forEach(function (h) {
        var r = (window.matchMedia("(pointer: coarse)").matches ? 14 : 8) * pixel;  // a finger's or a mouse's
        el("circle", { cx: h.at[0], cy: -h.at[1], r: r, class: "we-handle", "data-handle": h.name }, g);
      });
    }

    function handles(kind, it) {
      if (kind === "walls") return [{ name: "from", at: it.from }, { name: "to", at: it.to }];
      if (kind === "boxes" || kind === "zones") {
        var a = it.angle || 0, c = Math.cos(a), s = Math.sin(a), u = it.width / 2, v = it.height / 2;
        return [{ name: "corner", at: [it.x + u * c - v * s, it.y + u * s + v * c] }];
      }
      if (kind === "start") {
        var r = robotRadius() * 1.6;
        return [{ name: "heading", at: [it.x + Math.cos(it.theta) * r, it.y + Math.sin(it.theta) * r] }];
      }
      return [];
    }

    function describe() {
      var counts = KINDS.map(function (kind) { return list(kind).length; });
      return interpolate(gettext("Arena %(width)s × %(height)s m: %(walls)s walls, %(boxes)s boxes, %(zones)s zones, %(lines)s lines, %(landmarks)s landmarks, %(starts)s start poses"), {
        width: doc.size.width, height: doc.size.height, zones: counts[0], lines: counts[1], walls: counts[2],
        boxes: counts[3], landmarks: counts[4], starts: counts[5],
      }, true);
    }

    // -- the pointer ----------------------------------------------------------------------

    function worldPoint(event) {
      var p = svg.createSVGPoint();
      p.x = event.clientX;
      p.y = event.clientY;
      p = p.matrixTransform(svg.getScreenCTM().inverse());
      return [p.x, -p.y];
    }

    svg.addEventListener("pointerdown", function (event) {
      if (!event.isPrimary || event.button !== 0) return;
      event.preventDefault();
      if (event.pointerType !== "touch") svg.focus({ preventScroll: true });  // its keys: Delete, arrows
      var raw = worldPoint(event), p = snapPoint(raw);
      var handle = event.target.closest("[data-handle]");
      var hit = event.target.closest("[data-kind]");
      if (handle && selected) {
        drag = { mode: "handle", name: handle.dataset.handle };
      } else if (tool === "select" || !canEdit) {
        if (hit && hit.dataset.index >= 0) {
          select({ kind: hit.dataset.kind, index: Number(hit.dataset.index) });
          if (canEdit) drag = { mode: "move", from: p, original: JSON.stringify(item(selected)) };
        } else {
          select(null);
          if (zoom > 1) drag = { mode: "pan", at: [event.clientX, event.clientY], centre: centre.slice() };
        }
      } else {
        drag = { mode: "draw", from: p };
        draft = { kind: TOOL_KIND[tool], item: drafted(tool, p, p, raw) };
        render();
      }
      if (drag) svg.setPointerCapture(event.pointerId);
    });

    svg.addEventListener("pointermove", function (event) {
      if (!drag || !event.isPrimary) return;
      if (drag.mode === "pan") {
        centre = [drag.centre[0] - (event.clientX - drag.at[0]) * pixel, drag.centre[1] - (event.clientY - drag.at[1]) * pixel];
        render();
        return;
      }
      var raw = worldPoint(event), p = snapPoint(raw);
      if (drag.mode === "draw") draft.item = drafted(tool, drag.from, p, raw, draft.item);
      else if (drag.mode === "move") moveTo(JSON.parse(drag.original), p[0] - drag.from[0], p[1] - drag.from[1], raw);
      else reshape(item(selected), drag.name, p, raw);
      render();
      if (drag.mode !== "draw") fillForm();
    });

    svg.addEventListener("pointerup", function (event) {
      if (!drag || !event.isPrimary) return;
      var mode = drag.mode;
      drag = null;
      if (mode === "draw") finishDraft();
      else if (mode !== "pan") commit();
    });

    // Ctrl + the wheel (a touchpad's pinch) zooms where the pointer is.
    svg.addEventListener("wheel", function (event) {
      if (!event.ctrlKey) return;
      event.preventDefault();
      var p = worldPoint(event);
      zoomBy(Math.exp(-event.deltaY / 300), [p[0], -p[1]]);
    }, { passive: false });

    svg.addEventListener("pointercancel", function () {
      if (!drag) return;
      if (drag.mode !== "draw" && drag.mode !== "pan") doc = JSON.parse(history[at]);
      drag = draft = null;
      render();
      buildForm();
    });

    // The item a drag from `a` to `b` draws with `tool` (`previous`: the same drag's last one).
    function drafted(toolName, a, b, raw, previous) {
      switch (toolName) {
        case "wall": return { from: a, to: b, thickness: 0.05 };
        case "box": return Object.assign(rect(a, b), { angle: 0 });
        case "zone": return Object.assign({ name: "" }, rect(a, b), { colour: ZONE_COLOUR });
        case "line":
          if (!previous) return { points: [a], width: 0.03, colour: "#000000" };
          var last = previous.points[previous.points.length - 1];
          if (Math.hypot(b[0] - last[0], b[1] - last[1]) >= (snapping() ? step() : LINE_STEP) - 1e-9) previous.points.push(b);
          return previous;
        case "landmark": return onWall(raw, { text: "", size: 0.4, height: 0.3 });
        case "start":
          var far = Math.hypot(raw[0] - a[0], raw[1] - a[1]) > robotRadius();
          return { x: a[0], y: a[1], theta: far ? round(snapAngle(Math.atan2(raw[1] - a[1], raw[0] - a[0]))) : (previous ? previous.theta : round(Math.PI / 2)) };
      }
    }

    function rect(a, b) {
      return { x: round((a[0] + b[0]) / 2), y: round((a[1] + b[1]) / 2), width: round(Math.abs(b[0] - a[0])), height: round(Math.abs(b[1] - a[1])) };
    }

    function finishDraft() {
      var kind = draft.kind, it = draft.item;
      draft = null;
      if (!bigEnough(kind, it)) { render(); return; }
      if (kind === "zones") it.name = unique(gettext("zone %(n)s"), doc.zones.map(function (z) { return z.name; }));
      if (kind === "landmarks") it.text = unique(gettext("mark %(n)s"), doc.landmarks.map(function (l) { return l.text; }));
      list(kind).push(it);
      selected = { kind: kind, index: list(kind).length - 1 };
      commit();
      buildForm();
    }

    function bigEnough(kind, it) {
      if (kind === "walls") return Math.hypot(it.to[0] - it.from[0], it.to[1] - it.from[1]) >= MIN_SIZE;
      if (kind === "boxes" || kind === "zones") return it.width >= MIN_SIZE && it.height >= MIN_SIZE;
      if (kind === "lines") return it.points.length >= 2;
      return true;
    }

    function unique(pattern, taken) {
      for (var n = 1; ; n++) {
        var name = interpolate(pattern, { n: n }, true);
        if (taken.indexOf(name) < 0) return name;
      }
    }

    // Moves the selected item, as it was when the drag began, by (dx, dy).
    function moveTo(original, dx, dy, raw) {
      var kind = selected.kind, it = original;
      function by(p) { return [round(p[0] + dx), round(p[1] + dy)]; }
      if (kind === "walls") { it.from = by(it.from); it.to = by(it.to); }
      else if (kind === "lines") it.points = it.points.map(by);
      else if (kind === "landmarks") it = onWall(raw || [it.x + dx, it.y + dy], it);  // slides along walls
      else { it.x = round(it.x + dx); it.y = round(it.y + dy); }
      list(kind)[selected.index] = it;
    }

    function reshape(it, name, p, raw) {
      if (name === "from" || name === "to") it[name] = p;
      else if (name === "heading") it.theta = round(snapAngle(Math.atan2(raw[1] - it.y, raw[0] - it.x)));
      else if (name === "corner") {
        // The opposite corner stays where it is, in the item's own (turned) frame.
        var a = it.angle || 0, u = [Math.cos(a), Math.sin(a)], v = [-Math.sin(a), Math.cos(a)];
        var fixed = [it.x - u[0] * it.width / 2 - v[0] * it.height / 2, it.y - u[1] * it.width / 2 - v[1] * it.height / 2];
        var d = [p[0] - fixed[0], p[1] - fixed[1]];
        var w = Math.max(MIN_SIZE, d[0] * u[0] + d[1] * u[1]), h = Math.max(MIN_SIZE, d[0] * v[0] + d[1] * v[1]);
        it.width = round(w);
        it.height = round(h);
        it.x = round(fixed[0] + u[0] * w / 2 + v[0] * h / 2);
        it.y = round(fixed[1] + u[1] * w / 2 + v[1] * h / 2);
      }
    }

    // A landmark stands on the face of the wall nearest `p` (an inner one or the arena's),
    // facing the side `p` is on.
    function onWall(p, mark) {
      var best = null;
      walls().forEach(function (wall) {
        var a = wall[0], b = wall[1], dx = b[0] - a[0], dy = b[1] - a[1], len2 = dx * dx + dy * dy;
        if (!len2) return;
        var t = Math.max(0, Math.min(1, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2));
        var q = [a[0] + t * dx, a[1] + t * dy], dist = Math.hypot(p[0] - q[0], p[1] - q[1]);
        if (best && dist >= best.dist) return;
        var len = Math.sqrt(len2), n = [-dy / len, dx / len];
        if ((p[0] - q[0]) * n[0] + (p[1] - q[1]) * n[1] < 0) n = [-n[0], -n[1]];
        if (wall[3]) n = wall[3];  // the arena's walls face inwards whatever side p is on
        best = { dist: dist, at: [q[0] + n[0] * wall[2] / 2, q[1] + n[1] * wall[2] / 2], n: n };
      });
      return Object.assign({}, mark, { x: round(best.at[0]), y: round(best.at[1]), facing: round(Math.atan2(best.n[1], best.n[0])) });
    }

    // Every wall as [from, to, thickness, inward normal (the arena's only)].
    function walls() {
      var w = doc.size.width / 2, h = doc.size.height / 2;
      return [
        [[-w, -h], [w, -h], 0, [0, 1]], [[w, -h], [w, h], 0, [-1, 0]],
        [[w, h], [-w, h], 0, [0, -1]], [[-w, h], [-w, -h], 0, [1, 0]],
      ].concat(doc.walls.map(function (wall) { return [wall.from, wall.to, wall.thickness || 0.05, null]; }));
    }

    // -- selection, deleting, the keyboard --------------------------------------------------

    function select(sel) {
      selected = sel;
      deleteButton.disabled = !canEdit || !selected;
      render();
      buildForm();
    }

    function deleteSelected() {
      if (!canEdit || !selected) return;
      if (selected.kind === "start" && doc.start.length === 1) {
        say(gettext("A world needs a start pose: move this one instead."), "error");
        return;
      }
      list(selected.kind).splice(selected.index, 1);
      selected = null;
      commit();
      buildForm();
    }

    function useTool(name) {
      if (!canEdit && name !== "select") return;
      tool = name;
      toolButtons.forEach(function (b) { b.setAttribute("aria-pressed", String(b.dataset.tool === name)); });
      hint.textContent = HINTS[name]();
      svg.dataset.tool = name;
      render();
    }

    var HINTS = {
      select: function () { return canEdit ? gettext("Click an item to select it; drag it to move it, or drag its handles. Arrow keys move the selected item, Delete removes it.") : gettext("Click an item to see its properties."); },
      wall: function () { return gettext("Drag from one end of the wall to the other."); },
      box: function () { return gettext("Drag from one corner of the box to the opposite one."); },
      zone: function () { return gettext("Drag from one corner of the zone to the opposite one."); },
      line: function () { return gettext("Drag to paint a line on the floor."); },
      landmark: function () { return gettext("Click beside a wall: the landmark stands on it, facing you. Its text is in the form."); },
      start: function () { return gettext("Press where the robot starts and drag towards where it faces."); },
    };

    toolButtons.forEach(function (button) {
      button.addEventListener("click", function () { useTool(button.dataset.tool); });
    });

    // Arrow keys move along the toolbar (the ARIA toolbar's keys); Tab leaves it.
    document.querySelectorAll("[role=toolbar]").forEach(function (bar) {
      bar.addEventListener("keydown", function (event) {
        if (event.key !== "ArrowLeft" && event.key !== "ArrowRight") return;
        var buttons = Array.prototype.filter.call(bar.querySelectorAll("button"), function (b) { return !b.disabled && !b.hidden; });
        var i = buttons.indexOf(document.activeElement);
        if (i < 0) return;
        event.preventDefault();
        buttons[(i + (event.key === "ArrowRight" ? 1 : buttons.length - 1)) % buttons.length].focus();
      });
    });

    var SHORTCUTS = { v: "select", w: "wall", b: "box", z: "zone", l: "line", m: "landmark", s: "start" };

    document.addEventListener("keydown", function (event) {
      var typing = event.target.closest("input, textarea, select");
      var ctrl = event.ctrlKey || event.metaKey;
      var key = event.key.toLowerCase();
      if (ctrl && key === "s") { event.preventDefault(); save(); return; }
      if (typing) return;  // a field's own undo and keys
      if (ctrl && key === "z") { event.preventDefault(); restore(event.shiftKey ? 1 : -1); return; }
      if (ctrl && key === "y") { event.preventDefault(); restore(1); return; }
      if (ctrl || event.altKey) return;
      if (event.key === "Escape") { if (drag) svg.dispatchEvent(new Event("pointercancel")); select(null); return; }
      if (event.target === svg || event.target === document.body) {
        if ((event.key === "Delete" || event.key === "Backspace") && selected) { event.preventDefault(); deleteSelected(); return; }
        var arrow = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] }[event.key];
        if (arrow && selected && canEdit) { event.preventDefault(); nudge(arrow); return; }
        if (arrow && zoom > 1) { event.preventDefault(); pan(arrow); return; }
        if (event.key === "+" || event.key === "=") { zoomBy(1.5); return; }
        if (event.key === "-") { zoomBy(1 / 1.5); return; }
        if (event.key === "0") { zoom = 1; render(); return; }
        if (event.key === "Enter" && event.target === svg && tool !== "select" && canEdit) { event.preventDefault(); addAtCentre(); return; }
      }
      if (SHORTCUTS[key]) useTool(SHORTCUTS[key]);
    });

    function pan(direction) {
      var box = viewBox();
      centre = [centre[0] + direction[0] * box[2] / 5, centre[1] - direction[1] * box[3] / 5];
      render();
    }

    // The keyboard's way to move: one grid step (a centimetre without the grid).
    function nudge(direction) {
      var by = snapping() ? step() : 0.01;
      moveTo(JSON.parse(JSON.stringify(item(selected))), direction[0] * by, direction[1] * by, null);
      commit();
      fillForm();
    }

    // The keyboard's way to draw: an item of the tool's kind in the middle, to edit in the form.
    function addAtCentre() {
      var s = Math.min(1, doc.size.width / 4, doc.size.height / 4);
      var sizes = { wall: [[-s / 2, 0], [s / 2, 0]], box: [[-s / 4, -s / 4], [s / 4, s / 4]], zone: [[-s / 2, -s / 4], [s / 2, s / 4]], line: [[-s / 2, 0], [s / 2, 0]] };
      var ab = sizes[tool] || [[0, 0], [0, 0]];
      var it = drafted(tool, ab[0], ab[1], tool === "landmark" ? [doc.size.width / 2, 0] : ab[1]);
      if (tool === "line") it = drafted(tool, ab[0], ab[1], ab[1], it);
      draft = { kind: TOOL_KIND[tool], item: it };
      finishDraft();
      document.getElementById("we-form").querySelector("input:not([disabled])").focus();
    }

    document.getElementById("we-zoom-in").addEventListener("click", function () { zoomBy(1.5); });
    document.getElementById("we-zoom-out").addEventListener("click", function () { zoomBy(1 / 1.5); });
    document.getElementById("we-zoom-fit").addEventListener("click", function () { zoom = 1; render(); });
    undoButton.addEventListener("click", function () { restore(-1); });
    redoButton.addEventListener("click", function () { restore(1); });
    deleteButton.addEventListener("click", deleteSelected);
    snapBox.addEventListener("change", render);
    gridInput.addEventListener("change", render);

    // -- the side form --------------------------------------------------------------------

    // A field: [key in the item (dots for nested), its label, its type]; "deg" is an angle
    // the document keeps in radians, "pair" an [x, y] point.
    var FIELDS = {
      world: [["title", gettext("Title"), "text"], ["name", gettext("Name (letters, digits and -)"), "text"],
        ["size.width", gettext("Arena width (m)"), "m"], ["size.height", gettext("Arena height (m)"), "m"],
        // The world's robot (rhal.simulator's RobotSpec): a field left empty is its default.
        ["-", gettext("The world's robot")],
        ["robot.radius", gettext("Radius (m)"), "m", 0.15],
        ["robot.floor_sensor", gettext("Floor sensor (colour and lines, 0.1 m ahead)"), "bool"],
        ["robot.sonar", gettext("Sonar ring: angles from ahead (°, counter-clockwise; empty: none)"), "list"],
        ["robot.range.cone_deg", gettext("Range sensor's cone (°)"), "n", 15],
        ["robot.range.max", gettext("Range sensor's reach (m)"), "m", 4]],
      walls: [["from", gettext("From x, y (m)"), "pair"], ["to", gettext("To x, y (m)"), "pair"], ["thickness", gettext("Thickness (m)"), "m"]],
      boxes: [["x", gettext("Centre x (m)"), "m"], ["y", gettext("Centre y (m)"), "m"], ["width", gettext("Width (m)"), "m"],
        ["height", gettext("Depth (m)"), "m"], ["angle", gettext("Angle (°)"), "deg"]],
      zones: [["name", gettext("Name"), "text"], ["colour", gettext("Floor colour"), "colour?"], ["x", gettext("Centre x (m)"), "m"],
        ["y", gettext("Centre y (m)"), "m"], ["width", gettext("Width (m)"), "m"], ["height", gettext("Depth (m)"), "m"]],
      lines: [["colour", gettext("Colour"), "colour"], ["width", gettext("Width (m)"), "m"]],
      landmarks: [["text", gettext("Text (its QR code says it)"), "text"], ["x", gettext("x (m)"), "m"], ["y", gettext("y (m)"), "m"],
        ["facing", gettext("Facing (°)"), "deg"], ["size", gettext("Size (m)"), "m"], ["height", gettext("Height above the floor (m)"), "m"]],
      start: [["x", gettext("x (m)"), "m"], ["y", gettext("y (m)"), "m"], ["theta", gettext("Heading (°, 0 = east, 90 = north)"), "deg"]],
    };
    var POSITIVE = ["size.width", "size.height", "width", "height", "thickness", "size", "robot.radius"];
    var TITLES = {
      world: function () { return gettext("The world"); },
      walls: function (i) { return interpolate(gettext("Wall %(n)s"), { n: i + 1 }, true); },
      boxes: function (i) { return interpolate(gettext("Box %(n)s"), { n: i + 1 }, true); },
      zones: function (i) { return interpolate(gettext("Zone %(n)s"), { n: i + 1 }, true); },
      lines: function (i) { return interpolate(gettext("Line %(n)s"), { n: i + 1 }, true); },
      landmarks: function (i) { return interpolate(gettext("Landmark %(n)s"), { n: i + 1 }, true); },
      start: function (i) { return i === 0 ? gettext("Start pose 1 (where the robot starts)") : interpolate(gettext("Start pose %(n)s"), { n: i + 1 }, true); },
    };

    function target() { return selected ? item(selected) : doc; }
    function fields() { return FIELDS[selected ? selected.kind : "world"]; }

    function getPath(obj, key) { return key.split(".").reduce(function (o, k) { return o == null ? o : o[k]; }, obj); }
    // Sets obj's nested key (making the objects on its way); undefined removes it.
    function setPath(obj, key, value) {
      var keys = key.split("."), last = keys.pop();
      var parent = keys.reduce(function (o, k) {
        if (!o[k] || typeof o[k] !== "object") o[k] = {};
        return o[k];
      }, obj);
      if (value === undefined) delete parent[last];
      else parent[last] = value;
    }

    function buildForm() {
      while (form.firstChild) form.removeChild(form.firstChild);
      var kind = selected ? selected.kind : "world";
      var heading = document.createElement("h2");
      heading.id = "we-form-title";
      heading.textContent = TITLES[kind](selected && selected.index);
      form.appendChild(heading);
      // The message by its field, or at the top when no field of the form is the one it names
      // (a line's points, the robot's settings).
      var byField = error && fields().some(function (f) { return f[0] === error.field; });
      if (selectedIsError() && !byField) form.appendChild(errorNote(error.message));
      fields().forEach(function (field) { form.appendChild(field[0] === "-" ? subheading(field[1]) : fieldRow(field)); });
      if (selected && selected.kind === "start" && selected.index > 0 && canEdit) {
        form.appendChild(button(gettext("Make it the start pose"), function () {
          doc.start.unshift(doc.start.splice(selected.index, 1)[0]);
          selected = { kind: "start", index: 0 };
          commit();
          buildForm();
        }));
      }
      if (selected && canEdit) {
        form.appendChild(button(gettext("Delete"), deleteSelected, "danger"));
      }
      if (!selected) {
        var note = document.createElement("p");
        note.className = "muted";
        note.textContent = canEdit ? gettext("Select an item on the drawing to edit it here.") : gettext("This world is shown to read: copy it to change it.");
        form.appendChild(note);
      }
      fillForm();
    }

    function button(text, action, cls) {
      var b = document.createElement("button");
      b.type = "button";
      b.textContent = text;
      if (cls) b.className = cls;
      b.addEventListener("click", action);
      return b;
    }

    function subheading(text) {
      var h = document.createElement("h3");
      h.textContent = text;
      return h;
    }

    function errorNote(message) {
      var p = document.createElement("p");
      p.className = "we-error";
      p.id = "we-error";
      p.setAttribute("role", "alert");
      p.textContent = message;
      return p;
    }

    function fieldRow(field) {
      var key = field[0], type = field[2];
      var row = document.createElement("div");
      row.className = "we-field";
      row.dataset.key = key;
      var id = "we-f-" + key.replace(/\./g, "-");
      var lab = document.createElement("label");
      lab.textContent = field[1];
      row.appendChild(lab);
      var inputs = type === "pair" ? [input(id + "-x", "number"), input(id + "-y", "number")]
        : [input(id, { text: "text", list: "text", bool: "checkbox", colour: "color", "colour?": "color" }[type] || "number")];
      if (field[3] !== undefined) inputs[0].placeholder = field[3];  // the default, when empty
      lab.htmlFor = inputs[0].id;
      if (type === "bool") row.classList.add("we-check");
      if (type === "pair") {
        inputs[0].setAttribute("aria-label", field[1] + " x");
        inputs[1].setAttribute("aria-label", field[1] + " y");
      }
      var box = document.createElement("div");
      box.className = "we-inputs";
      inputs.forEach(function (i) {
        if (i.type === "number") i.step = type === "deg" ? "1" : "any";
        i.dataset.key = key;
        i.dataset.type = type;
        box.appendChild(i);
      });
      if (type === "colour?") {
        var none = document.createElement("label");
        var check = input(id + "-none", "checkbox");
        check.dataset.key = key;
        check.dataset.type = "none";
        none.appendChild(check);
        none.appendChild(document.createTextNode(" " + gettext("unpainted")));
        box.appendChild(none);
      }
      row.appendChild(box);
      if (error && error.field === key && selectedIsError()) {
        var note = errorNote(error.message);
        row.appendChild(note);
        inputs.forEach(function (i) { i.setAttribute("aria-invalid", "true"); i.setAttribute("aria-describedby", note.id); });
      }
      return row;
    }

    function selectedIsError() {
      return error && (selected ? error.kind === selected.kind && error.index === selected.index : error.kind === null);
    }

    function input(id, type) {
      var i = document.createElement("input");
      i.id = id;
      i.type = type;
      i.disabled = !canEdit;
      return i;
    }

    // The form shows the selected item's values (or the world's), without touching a field
    // being typed in.
    function fillForm() {
      var it = target();
      form.querySelectorAll("input[data-key]").forEach(function (i) {
        if (i === document.activeElement && i.type !== "checkbox") return;
        var value = getPath(it, i.dataset.key), type = i.dataset.type;
        if (type === "pair") i.value = value ? round(value[i.id.slice(-1) === "x" ? 0 : 1]) : "";
        else if (type === "deg") i.value = Math.round((value || 0) * DEG * 10) / 10;
        else if (type === "none") i.checked = !value;
        else if (type.indexOf("colour") === 0) i.value = value || ZONE_COLOUR;
        else if (type === "m" || type === "n") i.value = value === undefined ? "" : round(value);
        else if (type === "bool") i.checked = !!value;
        else if (type === "list") i.value = (value || []).join(", ");
        else i.value = value === undefined || value === null ? "" : value;
      });
    }

    function readField(i) {
      var key = i.dataset.key, type = i.dataset.type, it = target();
      if (type === "text" || type === "colour") { setPath(it, key, i.value); return; }
      if (type === "colour?") { setPath(it, key, i.value); form.querySelector("input[data-type=none]").checked = false; return; }
      if (type === "none") { setPath(it, key, i.checked ? null : form.querySelector("input[data-type='colour?']").value); return; }
      if (type === "bool") { setPath(it, key, i.checked); return; }
      if (type === "list") {
        var numbers = i.value.split(/[\s,;]+/).filter(Boolean).map(Number);
        if (numbers.every(isFinite)) setPath(it, key, numbers);
        return;
      }
      if (i.value === "" && i.placeholder) { setPath(it, key, undefined); return; }  // back to the default
      if (i.value === "" || !isFinite(Number(i.value))) return;
      var n = Number(i.value);
      if (n <= 0 && POSITIVE.indexOf(key) >= 0) return;  // a size: the drawing needs one
      if (type === "pair") getPath(it, key)[i.id.slice(-1) === "x" ? 0 : 1] = n;
      else setPath(it, key, type === "deg" ? round(n / DEG) : n);
    }

    form.addEventListener("input", function (event) {
      if (!canEdit || !event.target.dataset.key) return;
      readField(event.target);
      render();
    });
    form.addEventListener("change", function (event) {
      if (!canEdit || !event.target.dataset.key) return;
      readField(event.target);
      commit();
      buildFormKeepingFocus();
    });
    form.addEventListener("submit", function (event) { event.preventDefault(); });

    function buildFormKeepingFocus() {
      var focused = document.activeElement && form.contains(document.activeElement) ? document.activeElement.id : null;
      buildForm();
      if (focused && document.getElementById(focused)) document.getElementById(focused).focus();
    }

    // -- saving ---------------------------------------------------------------------------

    // Resolves true once the document is stored.
    function save() {
      if (!canEdit || busy) return Promise.resolve(false);
      busy = true;
      say(gettext("Saving…"), "busy");
      if (!doc.name) { doc.name = slug(doc.title) || "world"; commit(); }
      var body = JSON.stringify(doc);
      return send(worldId ? data.api + "/" + worldId : data.api, worldId ? "PUT" : "POST", body).then(function (response) {
        return response.json().then(function (answer) { answered(response, answer, body); return response.ok; },
          function () { say(interpolate(gettext("The server answered %(status)s"), { status: response.status }, true), "error"); return false; });
      }, function () {
        say(gettext("Not saved: the server cannot be reached. Your drawing is still here."), "error");
        return false;
      }).finally(function () { busy = false; });
    }

    function send(url, method, body) {
      return fetch(url, {
        method: method, body: body, credentials: "same-origin",
        headers: { "Content-Type": "application/json", "X-CSRFToken": window.robotideCookie("csrftoken") },
      });
    }

    // A sim of the user's own in this world (saved first), and to its page: where a teacher
    // tries what she drew.
    function tryInSim() {
      var stored = canEdit && (!worldId || history[at] !== savedText) ? save() : Promise.resolve(true);
      stored.then(function (ok) {
        if (!ok || busy) return;
        busy = true;
        say(gettext("Making a sim in this world…"), "busy");
        send("/api/sims", "POST", JSON.stringify({ world: worldId || data.builtin })).then(function (response) {
          return response.json().then(function (answer) {
            if (response.ok) window.location.assign("/robots/" + encodeURIComponent(answer.name) + "/");
            else say(typeof answer.detail === "string" ? answer.detail : gettext("Failed"), "error");
          });
        }, function () {
          say(gettext("The server cannot be reached."), "error");
        }).finally(function () { busy = false; });
      });
    }

    function answered(response, answer, body) {
      if (response.ok) {
        // The stored name is the document's as a slug: the next save sends that one.
        var sent = JSON.parse(body);
        if (answer.name) sent.name = answer.name;
        savedText = JSON.stringify(sent);
        if (answer.name && answer.name !== doc.name) { doc.name = answer.name; commit(); }
        if (!worldId && answer.id) {
          worldId = answer.id;
          window.history.replaceState(null, "", data.edit_url.replace("0", String(worldId)));
        }
        error = null;
        say(gettext("Saved"), "saved");
        changed();
        buildForm();
        return;
      }
      if (response.status === 401 || response.status === 403) {
        say(answer.detail || gettext("Not allowed."), "error");
        return;
      }
      var refusal = refused(answer);
      if (response.status === 409) refusal = { kind: null, index: null, field: "name", message: refusal.message };
      error = refusal;
      say(refusal.message, "error");
      selected = refusal.kind ? { kind: refusal.kind, index: refusal.index } : null;  // the world's form
      render();
      buildForm();
      // The field to mend, if the message names one; else the message, in view.
      var invalid = form.querySelector("input[aria-invalid=true]");
      if (invalid) invalid.focus();
      else if (document.getElementById("we-error")) document.getElementById("we-error").scrollIntoView({ block: "nearest" });
    }

    // The API's refusal as {kind, index, field, message}: its detail is a list of
    // {"loc": [...], "path": "walls[2].to", "msg"} (a plain message for other refusals).
    function refused(answer) {
      var detail = answer.detail, message = "", path = answer.path || "";
      if (Array.isArray(detail)) {
        message = detail.map(function (d) { return d.msg; }).join("; ");
        if (!path && detail[0]) path = detail[0].path || (detail[0].loc ? locPath(detail[0].loc) : "");
      } else if (detail && typeof detail === "object") {
        message = detail.message || detail.msg || "";
        path = path || detail.path || "";
      } else {
        message = String(detail || answer.error || gettext("Failed"));
      }
      var match = /^(walls|boxes|landmarks|lines|zones|start)\[(\d+)\](?:\.(\w+))?/.exec(path);
      if (match && doc[match[1]][Number(match[2])]) return { kind: match[1], index: Number(match[2]), field: match[3] || null, message: message };
      var key = path.replace(/\[\d+\].*$/, "");  // "robot.sonar[2]": the sonar's field
      if (key === "size") key = "size.width";
      var known = FIELDS.world.some(function (f) { return f[0] === key; });
      return { kind: null, index: null, field: known ? key : null, message: message };
    }

    function locPath(loc) {
      var parts = loc.filter(function (p) { return p !== "body" && p !== "payload"; });
      return parts.reduce(function (text, p) { return typeof p === "number" ? text + "[" + p + "]" : (text ? text + "." : "") + p; }, "");
    }

    function slug(text) {
      return (text || "").toLowerCase().normalize("NFD").replace(/[\u0300-\u036f]/g, "").replace(/[^a-z0-9]+/g, "-").replace(/^-|-$/g, "").slice(0, 50);
    }

    saveButton.addEventListener("click", save);
    document.getElementById("we-try").addEventListener("click", tryInSim);
    if (copyButton) {
      copyButton.addEventListener("click", function () {
        canEdit = true;
        worldId = null;
        doc.name = slug(interpolate(gettext("copy of %(name)s"), { name: doc.name }, true));
        doc.title = interpolate(gettext("Copy of %(title)s"), { title: doc.title || doc.name }, true);
        copyButton.hidden = true;
        saveButton.hidden = false;
        document.querySelector(".world-editor").classList.remove("read-only");
        toolButtons.forEach(function (b) { b.disabled = false; });
        commit();
        useTool("select");
        buildForm();
        say(gettext("A copy: save it to keep it as your own world."), "dirty");
      });
    }

    window.addEventListener("beforeunload", function (event) {
      if (canEdit && history[at] !== savedText) event.preventDefault();
    });
    window.addEventListener("resize", render);

    if (!canEdit) toolButtons.forEach(function (b) { if (b.dataset.tool !== "select") b.disabled = true; });
    useTool("select");
    changed();
    buildForm();
  }

  // A document as the editor needs it: every list present, numbers where numbers go.
  function normalised(world) {
    var doc = JSON.parse(JSON.stringify(world || {}));
    doc.format = doc.format || 1;
    doc.size = doc.size || { width: 4, height: 4 };
    KINDS.forEach(function (kind) { if (!Array.isArray(doc[kind])) doc[kind] = []; });
    if (!doc.start.length) doc.start.push({ x: 0, y: 0, theta: Math.PI / 2 });
    doc.boxes.forEach(function (b) { if (b.angle === undefined) b.angle = 0; });
    doc.walls.forEach(function (w) { if (w.thickness === undefined) w.thickness = 0.05; });
    doc.start.forEach(function (s) { if (s.theta === undefined) s.theta = 0; });
    return doc;
  }
})();
