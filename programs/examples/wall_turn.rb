# Drive ahead until the wall is near, turn away, and report the heading.
require 'robot'

bot = Robot.new
STOP_AT = 0.5 # metres

bot.drive(0.3, 0)
sleep 0.02 until bot.sensors['range'] < STOP_AT # poll every 20 ms
bot.stop

bot.drive(0, 1.0) # turn on the spot at 1 rad/s ...
sleep 1.5         # ... for about 1.5 s
bot.stop

heading = bot.sensors['heading'].round(1) # degrees, 1 decimal
puts "heading: #{heading}"
bot.show('heading', heading)
