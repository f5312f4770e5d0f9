# Anda até a parede, vira para longe dela e diz o rumo.

package require robot

robot::drive 0.3 0
while {[dict get [robot::sensors] range] >= 0.5} {  ;# metros
    after 20
}
robot::stop

robot::drive 0 1.0  ;# gira a 1 rad/s
after 1500
robot::stop

set rumo [format %.1f [dict get [robot::sensors] heading]]
puts "rumo: $rumo"
robot::show rumo $rumo
