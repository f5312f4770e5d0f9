# Drive ahead until the wall is near, turn away, and report the heading.
use strict;
use warnings;
use Time::HiRes qw(sleep);
use Robot;

my $bot     = Robot->new;
my $STOP_AT = 0.5;    # metres

$bot->drive(0.3, 0);
sleep 0.02 until $bot->sensors->{range} < $STOP_AT;    # poll every 20 ms
$bot->stop;

$bot->drive(0, 1.0);    # turn on the spot at 1 rad/s ...
sleep 1.5;              # ... for about 1.5 s
$bot->stop;

my $heading = sprintf '%.1f', $bot->sensors->{heading};    # degrees, 1 decimal
print "heading: $heading\n";
$bot->show('heading', 0 + $heading);    # 0+: show it as a number, not a text
