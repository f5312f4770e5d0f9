// Blocks for beginners: the robot's Blockly blocks, the toolbox, and mount() for a page.
//
// A page loads these, in this order, from our static files (no build step, no node):
//   vendor/blockly/blockly_compressed.js, vendor/blockly/blocks_compressed.js,
//   vendor/blockly/msg/en.js, robotide/blocks.js
// and then, once the element is in the page:
//   var editor = robotideBlocks.mount(element, jsonText, function (jsonText) { ... });
//
// - element: the workspace fills it, so it needs a size of its own (a height, e.g. 60vh).
// - jsonText: the program's source, Blockly's JSON serialization of a workspace
//   ({"blocks": {"languageVersion": 0, "blocks": [...]}, "variables": [...]}); "" or null for an
//   empty workspace. Text that is not JSON, or blocks this file does not define, throw an Error.
// - onChange(jsonText): called after every change the user makes to the program (not for
//   selecting, scrolling or zooming, nor for the load itself) with the whole workspace as JSON
//   text, e.g. to put it in the form's textarea that is saved.
// - returns {workspace, save(): jsonText, load(jsonText), resize(), dispose()}; call resize()
//   after the element changes size other than with the window.
// The program is the top stack (as the blocks lie, Blockly's reading order): every other top
// block is loose, greyed out with a warning and not run (the server decides so too).
// A 4th argument, options, is passed on to Blockly.inject (e.g. {readOnly: true}).
//
// What runs is the Python the server makes of the JSON (programs/blocks.py): the block types,
// field and input names here are what it reads. A block changed here changes there too.
(function () {
  "use strict";

  var script = document.currentScript && document.currentScript.src;
  // Blockly's sprites, cursors and sounds, from our copy: never from Blockly's demo server.
  var MEDIA = script ? new URL("../vendor/blockly/media/", script).href
                     : "/static/vendor/blockly/media/";

  var ROBOT_HUE = 20;
  var SENSORS_HUE = 45;
  var MESSAGES_HUE = 290;

  var SENSORS = [
    [gettext("range (m)"), "range"],
    [gettext("heading (degrees)"), "heading"],
    [gettext("bumper pressed"), "bumper"],
    [gettext("position x (m)"), "position.x"],
    [gettext("position y (m)"), "position.y"],
    [gettext("position angle (rad)"), "position.theta"],
    [gettext("speed (m/s)"), "velocity.linear"],
    [gettext("turning speed (rad/s)"), "velocity.angular"],
    [gettext("distance travelled (m)"), "odometry.distance"],
    [gettext("battery (%)"), "battery"],
  ];

  function statement(block) {
    block.previousStatement = null;
    block.nextStatement = null;
    block.inputsInline = true;
    return block;
  }

  function value(block) {
    block.output = null;
    block.inputsInline = true;
    return block;
  }

  var BLOCKS = [
    statement({
      type: "robot_drive",
      message0: gettext("drive at %1 m/s, turning at %2 rad/s"),
      args0: [
        {type: "input_value", name: "LINEAR", check: "Number"},
        {type: "input_value", name: "ANGULAR", check: "Number"},
      ],
      colour: ROBOT_HUE,
      tooltip: gettext("Drive on at this speed (m/s, negative: backwards), turning at this rate (rad/s, positive: to the left), until told otherwise."),
    }),
    statement({
      type: "robot_stop",
      message0: gettext("stop"),
      colour: ROBOT_HUE,
      tooltip: gettext("Stop the motors."),
    }),
    statement({
      type: "robot_forward",
      message0: gettext("forward for %1 seconds at %2 m/s"),
      args0: [
        {type: "input_value", name: "SECONDS", check: "Number"},
        {type: "input_value", name: "SPEED", check: "Number"},
      ],
      colour: ROBOT_HUE,
      tooltip: gettext("Drive straight ahead for this many seconds, then stop."),
    }),
    statement({
      type: "robot_turn",
      message0: gettext("turn %1 by %2 degrees"),
      args0: [
        {type: "field_dropdown", name: "DIRECTION", options: [[gettext("left"), "LEFT"], [gettext("right"), "RIGHT"]]},
        {type: "input_value", name: "DEGREES", check: "Number"},
      ],
      colour: ROBOT_HUE,
      tooltip: gettext("Turn on the spot by this angle, timed at the robot's turning speed, then stop."),
    }),
    statement({
      type: "robot_wait",
      message0: gettext("wait %1 seconds"),
      args0: [{type: "input_value", name: "SECONDS", check: "Number"}],
      colour: ROBOT_HUE,
      tooltip: gettext("Wait this many seconds; the robot keeps doing what it was doing."),
    }),
    statement({
      type: "robot_show",
      message0: gettext("show %1 as %2"),
      args0: [
        {type: "input_value", name: "VALUE"},
        {type: "field_input", name: "NAME", text: gettext("value")},
      ],
      colour: ROBOT_HUE,
      tooltip: gettext("Show a number or a text under this name on the robot's page."),
    }),
    statement({
      type: "robot_say",
      message0: gettext("say %1"),
      args0: [{type: "input_value", name: "TEXT"}],
      colour: ROBOT_HUE,
      tooltip: gettext("Speak this aloud on the robot's computer (and show it on the robot's page)."),
    }),
    value({
      type: "robot_sensor",
      message0: gettext("sensor %1"),
      args0: [{type: "field_dropdown", name: "SENSOR", options: SENSORS}],
      colour: SENSORS_HUE,
      tooltip: gettext("What this sensor of the robot reads now. A robot without it stops the program with an error that says so."),
    }),
    statement({
      type: "robot_publish",
      message0: gettext("send %1 on topic %2"),
      args0: [
        {type: "input_value", name: "VALUE"},
        {type: "field_input", name: "TOPIC", text: gettext("news")},
      ],
      colour: MESSAGES_HUE,
      tooltip: gettext("Send this value to the programs on this robot that receive on this topic."),
    }),
    value({
      type: "robot_receive",
      message0: gettext("next message on topic %1, waiting up to %2 seconds"),
      args0: [
        {type: "field_input", name: "TOPIC", text: gettext("news")},
        {type: "input_value", name: "TIMEOUT", check: "Number"},
      ],
      colour: MESSAGES_HUE,
      tooltip: gettext("The next value sent on this topic since the program started; null if none comes in time (empty: wait for ever)."),
    }),
    statement({
      type: "robot_memory_set",
      message0: gettext("remember %1 as %2"),
      args0: [
        {type: "input_value", name: "VALUE"},
        {type: "field_input", name: "KEY", text: gettext("laps")},
      ],
      colour: MESSAGES_HUE,
      tooltip: gettext("Keep this value under this name, in the memory the robot's programs share."),
    }),
    value({
      type: "robot_memory_get",
      message0: gettext("remembered %1"),
      args0: [{type: "field_input", name: "KEY", text: gettext("laps")}],
      colour: MESSAGES_HUE,
      tooltip: gettext("The value kept under this name in the robot's shared memory, or null."),
    }),
  ];

  function number(n) {
    return {shadow: {type: "math_number", fields: {NUM: n}}};
  }

  function text(t) {
    return {shadow: {type: "text", fields: {TEXT: t}}};
  }

  function block(type, extra) {
    var entry = {kind: "block", type: type};
    for (var key in extra || {}) entry[key] = extra[key];
    return entry;
  }

  var TOOLBOX = {
    kind: "categoryToolbox",
    contents: [
      {kind: "category", name: gettext("Robot"), colour: ROBOT_HUE, contents: [
        block("robot_forward", {inputs: {SECONDS: number(1), SPEED: number(0.2)}}),
        block("robot_turn", {fields: {DIRECTION: "LEFT"}, inputs: {DEGREES: number(90)}}),
        block("robot_drive", {inputs: {LINEAR: number(0.2), ANGULAR: number(0)}}),
        block("robot_stop"),
        block("robot_wait", {inputs: {SECONDS: number(1)}}),
        block("robot_say", {inputs: {TEXT: text(gettext("hello"))}}),
        block("robot_show", {inputs: {VALUE: {block: {type: "robot_sensor",
                                                      fields: {SENSOR: "range"}}}},
                             fields: {NAME: gettext("range")}}),
      ]},
      {kind: "category", name: gettext("Sensors"), colour: SENSORS_HUE, contents: [
        block("robot_sensor", {fields: {SENSOR: "range"}}),
        block("robot_sensor", {fields: {SENSOR: "heading"}}),
        block("robot_sensor", {fields: {SENSOR: "bumper"}}),
        block("robot_sensor", {fields: {SENSOR: "position.x"}}),
      ]},
      {kind: "category", name: gettext("Logic"), categorystyle: "logic_category", contents: [
        block("controls_if"),
        block("controls_if", {extraState: {hasElse: true}}),
        block("logic_compare", {inputs: {B: number(0.4)}}),
        block("logic_operation"),
        block("logic_negate"),
        block("logic_boolean"),
        block("logic_null"),
      ]},
      {kind: "category", name: gettext("Loops"), categorystyle: "loop_category", contents: [
        block("controls_repeat_ext", {inputs: {TIMES: number(4)}}),
        block("controls_whileUntil"),
        block("controls_for", {inputs: {FROM: number(1), TO: number(10), BY: number(1)}}),
        block("controls_flow_statements"),
      ]},
      {kind: "category", name: gettext("Math"), categorystyle: "math_category", contents: [
        block("math_number", {fields: {NUM: 0}}),
        block("math_arithmetic", {inputs: {A: number(1), B: number(1)}}),
        block("math_random_int", {inputs: {FROM: number(1), TO: number(100)}}),
        block("math_round", {inputs: {NUM: number(3.1)}}),
      ]},
      {kind: "category", name: gettext("Text"), categorystyle: "text_category", contents: [
        block("text", {fields: {TEXT: gettext("hello")}}),
        block("text_join"),
        block("text_print", {inputs: {TEXT: text(gettext("hello"))}}),
      ]},
      {kind: "category", name: gettext("Variables"), categorystyle: "variable_category",
       custom: "VARIABLE"},
      {kind: "category", name: gettext("Messages"), colour: MESSAGES_HUE, contents: [
        block("robot_publish", {inputs: {VALUE: text(gettext("hello"))}}),
        block("robot_receive", {inputs: {TIMEOUT: number(5)}}),
        block("robot_memory_set", {inputs: {VALUE: number(0)}}),
        block("robot_memory_get"),
      ]},
    ],
  };

  Blockly.common.defineBlocksWithJsonArray(BLOCKS);

  // A block a run's error came from (blocks_bench.js marks it): outlined in red.
  Blockly.Css.register(
    ".robotide-error-block > .blocklyPath { stroke: #c62828 !important; stroke-width: 4px !important; }");

  // A warning's words in short lines: Blockly's bubble does not wrap them, and a long line
  // runs out of a phone's workspace.
  function wrap(text, width) {
    return text.split("\n").map(function (paragraph) {
      var lines = [], line = "";
      paragraph.split(" ").forEach(function (word) {
        if (line && (line + " " + word).length > (width || 32)) { lines.push(line); line = word; }
        else line = line ? line + " " + word : word;
      });
      return lines.concat(line).join("\n");
    }).join("\n");
  }

  // Blockly's own reason for orphans: programs/blocks.py reads it as loose too.
  var LOOSE = "ORPHANED_BLOCK";
  var LOOSE_WARNING = "robotide-loose";

  // The program: the top stack as the blocks lie; a value block alone cannot be one.
  function mainStack(workspace) {
    var tops = workspace.getTopBlocks(true);
    for (var i = 0; i < tops.length; i++) {
      if (!tops[i].outputConnection || tops[i].getNextBlock()) return tops[i];
    }
    return null;
  }

  // Grey out (disable) every loose top block, as Blockly's orphan-disabling does, and enable
  // again what is attached or has become the program. Not an undo step of its own.
  function markLoose(workspace) {
    var main = mainStack(workspace);
    var undo = Blockly.Events.getRecordUndo();
    Blockly.Events.setRecordUndo(false);
    try {
      workspace.getAllBlocks(false).forEach(function (block) {
        var loose = !block.getParent() && block !== main;
        if (block.hasDisabledReason(LOOSE) !== loose) block.setDisabledReason(loose, LOOSE);
        // (the warning is not saved with the block: told once for each block on this page)
        if (Boolean(block.robotideLoose) === loose || !block.setWarningText) return;
        block.robotideLoose = loose;
        block.setWarningText(loose ? wrap(gettext("Not attached to the program, so it does not run. The program is the top stack: attach this under it.")) : null, LOOSE_WARNING);
      });
    } finally {
      Blockly.Events.setRecordUndo(undo);
    }
  }

  function save(workspace) {
    return JSON.stringify(Blockly.serialization.workspaces.save(workspace), null, 2);
  }

  function load(workspace, jsonText) {
    var state = {};
    if (jsonText && jsonText.trim()) {
      try {
        state = JSON.parse(jsonText);
      } catch (error) {
        throw new Error(interpolate(gettext("This program is not blocks (Blockly's JSON): %(error)s"), {error: error.message}, true));
      }
    }
    Blockly.serialization.workspaces.load(state, workspace);
  }

  function mount(element, jsonText, onChange, options) {
    var settings = {
      toolbox: TOOLBOX,
      media: MEDIA,
      trashcan: true,
      sounds: true,
      zoom: {controls: true, wheel: false, startScale: 1.0},
      move: {scrollbars: true, drag: true, wheel: true},
      grid: {spacing: 25, length: 3, colour: "#ddd", snap: true},
    };
    for (var key in options || {}) settings[key] = options[key];
    var workspace = Blockly.inject(element, settings);
    try {
      load(workspace, jsonText);
    } catch (error) {
      workspace.dispose();
      throw error;
    }
    markLoose(workspace);
    var last = save(workspace);
    // Only changes to the program; the load's own events come after this and change nothing.
    workspace.addChangeListener(function (event) {
      if (event.isUiEvent || workspace.isDragging()) return;
      markLoose(workspace);  // its own change events come back here, and change nothing more
      var now = save(workspace);
      if (now === last) return;
      last = now;
      if (onChange) onChange(now);
    });
    return {
      workspace: workspace,
      save: function () { return save(workspace); },
      load: function (text) { load(workspace, text); markLoose(workspace); last = save(workspace); },
      resize: function () { Blockly.svgResize(workspace); },
      dispose: function () { workspace.dispose(); },
    };
  }

  window.robotideBlocks = {
    mount: mount,
    toolbox: TOOLBOX,
    blockTypes: BLOCKS.map(function (b) { return b.type; }),
    mainStack: mainStack,
    wrap: wrap,
  };
})();
