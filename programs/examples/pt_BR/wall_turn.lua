-- Anda até a parede, vira para longe dela e diz o rumo.

local socket = require('socket') -- para socket.sleep
local Robot = require('robot')

local bot = Robot.new()

bot:drive(0.3, 0)
while bot:sensors().range >= 0.5 do -- metros
  socket.sleep(0.02)
end
bot:stop()

bot:drive(0, 1.0) -- gira a 1 rad/s
socket.sleep(1.5)
bot:stop()

local rumo = tonumber(string.format('%.1f', bot:sensors().heading))
print(string.format('rumo: %.1f', rumo))
bot:show('rumo', rumo)
