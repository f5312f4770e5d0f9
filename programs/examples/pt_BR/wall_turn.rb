# Anda em frente até a parede ficar perto, vira para longe dela e diz o rumo.
require 'robot'

bot = Robot.new
PARAR_A = 0.5 # metros

bot.drive(0.3, 0)
sleep 0.02 until bot.sensors['range'] < PARAR_A # olha a cada 20 ms
bot.stop

bot.drive(0, 1.0) # gira no lugar a 1 rad/s ...
sleep 1.5         # ... por cerca de 1,5 s
bot.stop

rumo = bot.sensors['heading'].round(1) # graus, 1 casa decimal
puts "rumo: #{rumo}"
bot.show('rumo', rumo)
