"""I'm home: wander until the camera sees the "home" code, then say so and stop.

The paper's second example: barcode labels are landmarks a robot recognises with its camera.
In the simulator, QR codes with the names of rooms hang on the arena's walls. At each wall the
robot turns once round on the spot (by its compass), reading the codes in view, then sets off
the way chance says.
"""

import random
import time

import robot

HOME = "home"
SPEED = 0.25  # m/s
TURN = 0.8  # rad/s
bot = robot.Robot()
seen = set()


def home_in_view():
    """Read the codes in view; say which are new; True if one is home."""
    texts = [code["text"] for code in bot.scan_barcode()]
    for text in texts:
        if text not in seen:
            seen.add(text)
            print(f"I see: {text}", flush=True)
            bot.show("landmark", text)
    return HOME in texts


def look_around():
    """Turn once round on the spot, looking: True as soon as home is in view."""
    bot.drive(0.0, TURN)
    turned, last = 0.0, bot.sensor("heading")
    while turned < 360:
        if home_in_view():
            return True
        time.sleep(0.05)
        heading = bot.sensor("heading")
        turned += abs((heading - last + 540) % 360 - 180)
        last = heading
    return False


def wander():
    """Drive about until home is in view."""
    while not home_in_view():
        readings = bot.sensors()
        if readings["bumper"] or readings["range"] < 0.6:  # m: something ahead
            if readings["bumper"]:
                bot.drive(-0.15, 0.0)  # back off first
                time.sleep(0.4)
            if look_around():
                return
            bot.drive(0.0, random.choice((-TURN, TURN)))  # a new way, at random
            time.sleep(random.uniform(0.5, 3.0))
            while bot.sensor("range") < 0.6:  # and a clear one
                time.sleep(0.05)
        bot.drive(SPEED, 0.0)
        time.sleep(0.05)


wander()
bot.stop()
print("I'm home", flush=True)
bot.say("I'm home")
