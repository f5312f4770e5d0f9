#!/bin/sh
# The Robot API from the shell: the robot command prints what it reads.
echo "My heading is $(robot sensors heading) degrees"
robot drive 0.2 0
sleep 2
robot stop
echo "The wall ahead is $(robot sensors range) m away"
