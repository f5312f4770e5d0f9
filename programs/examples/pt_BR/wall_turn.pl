# Anda em frente até a parede ficar perto, vira para longe dela e diz o rumo.
use strict;
use warnings;
use Time::HiRes qw(sleep);
use Robot;

my $bot     = Robot->new;
my $PARAR_A = 0.5;    # metros

$bot->drive(0.3, 0);
sleep 0.02 until $bot->sensors->{range} < $PARAR_A;    # olha a cada 20 ms
$bot->stop;

$bot->drive(0, 1.0);    # gira no lugar a 1 rad/s ...
sleep 1.5;              # ... por cerca de 1,5 s
$bot->stop;

my $rumo = sprintf '%.1f', $bot->sensors->{heading};    # graus, 1 casa decimal
print "rumo: $rumo\n";
$bot->show('rumo', 0 + $rumo);    # 0+: mostra como número, não como texto
