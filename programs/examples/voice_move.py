"""Say "move" and the robot moves: spoken commands, recognised on the robot's computer, offline.

The paper's third example. Say "move" (ahead 20 cm), "left" or "right" (a quarter turn) or
"stop" (the robot tells how far the wall ahead is, and the program ends). Give WAV files in the
program's folder as arguments to play them to the robot instead of the microphone, in turn.

On the simulated robot, which has no microphone, type the command into the "Say to the robot"
box on the robot's page or beside the editor, and press Enter: listen() hears what is typed
there (on a robot with a microphone too, whichever comes first).
"""

import sys
import time

import robot

COMMANDS = ["move", "left", "right", "stop"]
bot = robot.Robot()


def commands():
    """What is heard, one command at a time ("" when it was none of them)."""
    recordings = sys.argv[1:]
    if recordings:
        for wav in recordings:
            yield bot.listen(wav=wav, words=COMMANDS)["text"]
        return
    bot.say("Say move, left, right or stop")
    while True:
        yield bot.listen(3, words=COMMANDS)["text"]


def move(linear, angular, seconds):
    bot.drive(linear, angular)
    time.sleep(seconds)
    bot.stop()


for command in commands():
    if not command:
        continue
    print(f"heard: {command}", flush=True)
    bot.show("heard", command)
    if command == "move":
        move(0.2, 0.0, 1.0)
    elif command == "left":
        move(0.0, 0.8, 1.96)  # about a quarter turn
    elif command == "right":
        move(0.0, -0.8, 1.96)
    else:
        bot.stop()
        bot.say(f"The range is {bot.sensor('range'):.1f} metres")
        break
