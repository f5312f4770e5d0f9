# Tcl package index for the robotide Robot API client: package require robot
package ifneeded robot 1.0 [list source [file join $dir robot.tcl]]
