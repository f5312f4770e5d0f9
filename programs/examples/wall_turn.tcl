# Drive to the wall, turn away from it, and tell the heading.

package require robot

robot::drive 0.3 0
while {[dict get [robot::sensors] range] >= 0.5} {  ;# metres
    after 20
}
robot::stop

robot::drive 0 1.0  ;# turn at 1 rad/s
after 1500
robot::stop

set heading [format %.1f [dict get [robot::sensors] heading]]
puts "heading: $heading"
robot::show heading $heading
