-- Drive to the wall, turn away from it, and tell the heading.

local socket = require('socket') -- for socket.sleep
local Robot = require('robot')

local bot = Robot.new()

bot:drive(0.3, 0)
while bot:sensors().range >= 0.5 do -- metres
  socket.sleep(0.02)
end
bot:stop()

bot:drive(0, 1.0) -- turn at 1 rad/s
socket.sleep(1.5)
bot:stop()

local heading = tonumber(string.format('%.1f', bot:sensors().heading))
print(string.format('heading: %.1f', heading))
bot:show('heading', heading)
