"""Read the compass, say the heading and draw a compass on the robot's page.

The paper's example 1, and the compass of its figure 6 drawn by user code.
"""

import math
import time

import robot

bot = robot.Robot()


def compass_svg(heading):
    angle = math.radians(heading)
    x, y = 50 + 26 * math.sin(angle), 50 - 26 * math.cos(angle)
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100" width="160" height="160">'
        '<circle cx="50" cy="50" r="45" fill="#fff" stroke="#334" stroke-width="3"/>'
        '<text x="50" y="17" text-anchor="middle" font-size="11" font-family="sans-serif">N</text>'
        f'<line x1="50" y1="50" x2="{x:.1f}" y2="{y:.1f}" stroke="#c22" stroke-width="5"'
        ' stroke-linecap="round"/><circle cx="50" cy="50" r="4" fill="#334"/></svg>'
    )


bot.drive(0.0, 0.4)  # turn slowly, so the needle moves
for _ in range(30):
    heading = bot.sensors()["heading"]
    print(f"My heading is {heading:.0f} degrees")
    bot.show("heading", round(heading) % 360)
    bot.show("compass", compass_svg(heading))
    time.sleep(1)
bot.stop()
