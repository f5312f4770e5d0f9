"""Robot API round trips per language: sensors() calls per second with each language's client.

One appliance; for each language of the registry (programs.languages.LANGUAGES), one program
in that language, run through the appliance like any user program, makes warm-up calls and
then times up to N `sensors()` calls with that language's own client (programs/clients/...)
and its own clock, and prints

    RATE <calls per second> P50 <median seconds per call> CALLS <calls timed>

which is read back from the run's log. The clocks: Python time.perf_counter, Perl
Time::HiRes clock_gettime(CLOCK_MONOTONIC), Ruby Process.clock_gettime(CLOCK_MONOTONIC),
Lua socket.gettime (luasocket; os.clock is CPU time), Node process.hrtime.bigint, Tcl
clock microseconds, bash $EPOCHREALTIME.

The shell's client is the `robot` command, a new process (a Python interpreter) per call, so
it makes far fewer calls. Every timed loop also stops after LIMIT seconds, and the module as a
whole after BUDGET seconds (the languages left are reported as skipped), so it stays well
under a minute. A language whose interpreter is not installed is reported as such.

Target: Python's, as in api_roundtrips (>= 10,000/s); the other languages' figures are
context ("-"), printed, never asserted.
"""

import re
import time

from benchmarks.common import Figure, appliance, print_table, say

BENCH = "5 languages"
TARGET = 10_000  # Python's, the same aim as api_roundtrips
CALLS = 5_000
WARMUP = 200
SHELL_CALLS = 100
SHELL_WARMUP = 5
LIMIT = 5.0  # seconds: a timed loop ends after this many even if it has not made its calls
RUN_TIMEOUT = 20.0  # one run, start to end
BUDGET = 50.0  # the whole module, appliance start included

# Placeholders @N@, @WARMUP@, @LIMIT@ (seconds) and @LIMIT_US@ (microseconds) are filled in.
PROGRAMS = {
    "python": """\
import time
import robot

bot = robot.Robot()
for _ in range(@WARMUP@):
    bot.sensors()
now = time.perf_counter
times = []
t = start = now()
while len(times) < @N@ and t - start < @LIMIT@:
    bot.sensors()
    t2 = now()
    times.append(t2 - t)
    t = t2
times.sort()
n = len(times)
print("RATE %.1f P50 %.6f CALLS %d" % (n / (t - start), times[n // 2], n))
""",
    "perl": """\
use strict;
use warnings;
use Time::HiRes qw(clock_gettime CLOCK_MONOTONIC);
use Robot;

my $bot = Robot->new;
$bot->sensors for 1 .. @WARMUP@;
my @times;
my $start = clock_gettime(CLOCK_MONOTONIC);
my $t = $start;
while (@times < @N@ && $t - $start < @LIMIT@) {
    $bot->sensors;
    my $t2 = clock_gettime(CLOCK_MONOTONIC);
    push @times, $t2 - $t;
    $t = $t2;
}
@times = sort { $a <=> $b } @times;
my $n = @times;
printf "RATE %.1f P50 %.6f CALLS %d\\n", $n / ($t - $start), $times[int($n / 2)], $n;
""",
    "ruby": """\
require 'robot'

bot = Robot.new
@WARMUP@.times { bot.sensors }
times = []
start = t = Process.clock_gettime(Process::CLOCK_MONOTONIC)
while times.size < @N@ && t - start < @LIMIT@
  bot.sensors
  t2 = Process.clock_gettime(Process::CLOCK_MONOTONIC)
  times << t2 - t
  t = t2
end
times.sort!
n = times.size
printf("RATE %.1f P50 %.6f CALLS %d\\n", n / (t - start), times[n / 2], n)
""",
    "lua": """\
local socket = require('socket')
local Robot = require('robot')

local bot = Robot.new()
for _ = 1, @WARMUP@ do bot:sensors() end
local now = socket.gettime -- os.clock would be CPU time
local times = {}
local start = now()
local t = start
while #times < @N@ and t - start < @LIMIT@ do
  bot:sensors()
  local t2 = now()
  times[#times + 1] = t2 - t
  t = t2
end
table.sort(times)
local n = #times
local median = times[math.floor(n / 2) + 1]
print(string.format('RATE %.1f P50 %.6f CALLS %d', n / (t - start), median, n))
""",
    "javascript": """\
const { Robot } = require('robot');

(async () => {
  const bot = new Robot();
  for (let i = 0; i < @WARMUP@; i++) await bot.sensors();
  const now = process.hrtime.bigint;
  const limit = BigInt(Math.round(@LIMIT@ * 1e9));
  const times = [];
  const start = now();
  let t = start;
  while (times.length < @N@ && t - start < limit) {
    await bot.sensors();
    const t2 = now();
    times.push(Number(t2 - t) / 1e9);
    t = t2;
  }
  times.sort((a, b) => a - b);
  const n = times.length;
  const rate = n / (Number(t - start) / 1e9);
  console.log(`RATE ${rate.toFixed(1)} P50 ${times[n >> 1].toFixed(6)} CALLS ${n}`);
  await bot.close();
})().catch((err) => {
  console.error(err);
  process.exit(1);
});
""",
    "tcl": """\
package require robot

for {set i 0} {$i < @WARMUP@} {incr i} { robot::sensors }
set times {}
set n 0
set start [clock microseconds]
set t $start
while {$n < @N@ && $t - $start < @LIMIT_US@} {
    robot::sensors
    set t2 [clock microseconds]
    lappend times [expr {$t2 - $t}]
    set t $t2
    incr n
}
set times [lsort -integer $times]
puts [format "RATE %.1f P50 %.6f CALLS %d" [expr {$n / (($t - $start) / 1e6)}] \\
    [expr {[lindex $times [expr {$n / 2}]] / 1e6}] $n]
""",
    # bash (the registry's first choice for the shell): $EPOCHREALTIME without its point is
    # microseconds, read without a subshell.
    "shell": """\
#!/bin/bash
for ((i = 0; i < @WARMUP@; i++)); do robot sensors >/dev/null || exit 1; done
times=()
n=0
start=${EPOCHREALTIME/[.,]/}
t=$start
while (( n < @N@ && t - start < @LIMIT_US@ )); do
  robot sensors >/dev/null || exit 1
  t2=${EPOCHREALTIME/[.,]/}
  times+=($((t2 - t)))
  t=$t2
  n=$((n + 1))
done
median=$(printf '%s\\n' "${times[@]}" | sort -n | sed -n "$((n / 2 + 1))p")
awk -v n="$n" -v us="$((t - start))" -v m="$median" \\
  'BEGIN { printf "RATE %.1f P50 %.6f CALLS %d\\n", n / (us / 1e6), m / 1e6, n }'
""",
}
RESULT_RE = re.compile(r"RATE ([\d.]+) P50 ([\d.]+) CALLS (\d+)")


def source(language: str) -> str:
    calls, warmup = (SHELL_CALLS, SHELL_WARMUP) if language == "shell" else (CALLS, WARMUP)
    text = PROGRAMS[language]
    for key, value in (
        ("@N@", calls),
        ("@WARMUP@", warmup),
        ("@LIMIT_US@", int(LIMIT * 1e6)),
        ("@LIMIT@", LIMIT),
    ):
        text = text.replace(key, str(value))
    return text


def parse(text: str) -> dict | None:
    m = RESULT_RE.search(text)
    if not m:
        return None
    return {"rate": float(m.group(1)), "p50": float(m.group(2)), "calls": int(m.group(3))}


def one(app, name: str, remaining: float) -> tuple[dict | None, str]:
    """Runs the language's program; its result (None if it printed none) and a note."""
    program = app.create_program(f"bench sensors calls {name}", source(name), language=name)
    t0 = time.monotonic()
    run_id = app.run_program(program["id"])["id"]
    try:
        ended = app.wait_run(run_id, timeout=max(1.0, min(RUN_TIMEOUT, remaining)))
    except Exception:
        app.api("POST", f"/api/runs/{run_id}/stop")
        return None, "the run did not end in time (stopped)"
    log_file = app.data_dir / "runs" / str(run_id) / "output.log"
    log = log_file.read_text(errors="replace") if log_file.exists() else ""
    result = parse(log)
    if result is None:
        tail = " | ".join(line for line in log.strip().splitlines()[-4:])
        return None, f"run {ended['state']} ({ended.get('reason')}), no RATE line: {tail[-300:]}"
    warmup, wanted = (SHELL_WARMUP, SHELL_CALLS) if name == "shell" else (WARMUP, CALLS)
    note = f"{result['calls']:,} calls after {warmup} warm-up"
    if result["calls"] < wanted:
        note += f" (of {wanted:,}: the {LIMIT:g} s limit came first)"
    note += f"; whole run {time.monotonic() - t0:.1f} s"
    if name == "shell":
        note += "; a `robot sensors` process per call"
    return result, note


def run() -> list[Figure]:
    from programs.languages import LANGUAGES

    started = time.monotonic()
    results: dict[str, tuple[dict | None, str]] = {}
    with appliance("languages") as app:
        for name, language in LANGUAGES.items():
            remaining = BUDGET - (time.monotonic() - started)
            if name not in PROGRAMS:
                results[name] = (None, "no benchmark program for this language")
            elif not language.available:
                results[name] = (None, f"not installed ({language.install_hint})")
            elif remaining < 5:
                results[name] = (None, f"skipped: the module's {BUDGET:g} s budget is spent")
            else:
                say(f"[{BENCH}] {name}: sensors() calls through the appliance")
                results[name] = one(app, name, remaining)
                if results[name][0] is None:
                    say(f"[{BENCH}] {name}: {results[name][1]}")

    figures: list[Figure] = []
    for name, (result, note) in results.items():
        rate = result and result["rate"]
        if name == "python":
            target, ok = f">= {TARGET:,}", rate is not None and rate >= TARGET
        else:
            target, ok = "-", None
        figures.append(
            Figure(BENCH, f"{name}: sensors() round trips/s", rate, "calls/s", target, ok, note)
        )
        if result:
            median = result["p50"] * 1e6
            figures.append(Figure(BENCH, f"  {name}: latency per call, median", median, "us"))
    return figures


if __name__ == "__main__":
    print_table(run())
