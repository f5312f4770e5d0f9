# Perl client for the robotide Robot API (core modules only).
#
#   use Robot;
#   my $bot = Robot->new;
#   $bot->drive(0.2, 0);                 # linear m/s, angular rad/s (clamped to the robot's limits)
#   print $bot->sensors->{heading}, "\n"; # compass, degrees
#   $bot->show('heading', 42);           # appears live on the robot's page
#   $bot->stop;
#
# Programs on the same robot talk through topics and a shared memory:
#   $bot->subscribe('ping');  my $value = $bot->receive('ping', 5);  # undef after 5 s
#   $bot->publish('ping', { n => 1 });
#   $bot->memory_set('best', 3.2);  $bot->memory_get('best');
#
# The robot's computer lends its senses and voice:
#   $bot->say("I'm home");                 # spoken, and shown on the robot's page
#   $bot->snapshot;                        # { jpeg => base64 text, width => .., height => .. }
#   $bot->scan_barcode;                    # [ { text => 'home', format => 'QRCode', position => [...] } ]
#   $bot->listen(3, undef, ['move', 'stop'])->{text};  # 'move', or '' when none was heard
#
# Any other method: $bot->call('method', @params). An error the robot reports dies with a
# Robot::Error object: $@->message, $@->code; as a string "robot: MESSAGE at FILE line N.".

package Robot::Error;

use strict;
use warnings;
use overload '""' => sub { "robot: $_[0]{message}$_[0]{where}" }, fallback => 1;

sub new {
    my ($class, %args) = @_;
    return bless { message => 'robot error', where => "\n", %args }, $class;
}

sub message { $_[0]{message} }
sub code    { $_[0]{code} }      # the JSON-RPC error code, undef for a connection error
sub data    { $_[0]{data} }

package Robot;

use strict;
use warnings;
use Carp ();
use IO::Socket::INET;
use IO::Socket::UNIX;
use JSON::PP ();
use Scalar::Util qw(looks_like_number);
use Socket qw(IPPROTO_TCP TCP_NODELAY);

our $VERSION = '1.0';

my $json = JSON::PP->new->utf8->allow_nonref;

sub new {
    my ($class, %args) = @_;
    my $address = $args{address} // $ENV{ROBOT_API};    # unix:/path or host:port
    my $token   = $args{token}   // $ENV{ROBOT_TOKEN};
    _fail('ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide')
        unless $address && $token;
    my $sock;
    if ($address =~ /^unix:(.+)$/) {
        $sock = IO::Socket::UNIX->new(Type => SOCK_STREAM, Peer => $1);
    }
    else {
        my ($host, $port) = $address =~ /^(.*):(\d+)$/
            or _fail("ROBOT_API is not unix:/path or host:port: $address");
        $sock = IO::Socket::INET->new(PeerAddr => $host || '127.0.0.1', PeerPort => $port,
            Proto => 'tcp');
        setsockopt($sock, IPPROTO_TCP, TCP_NODELAY, 1) if $sock;
    }
    _fail("cannot reach the robot at $address: $!") unless $sock;
    $sock->autoflush(1);
    my $self = bless { sock => $sock, next_id => 0 }, $class;
    $self->call('auth', $token);
    return $self;
}

sub call {
    my ($self, $method, @params) = @_;
    my $id = ++$self->{next_id};
    my $request = { jsonrpc => '2.0', id => $id, method => $method, params => \@params };
    local $SIG{PIPE} = 'IGNORE';    # a closed socket is an error below, not a silent death
    my $sock = $self->{sock} or _fail('this robot connection is closed');
    print {$sock} $json->encode($request), "\n"
        or _fail('the robot closed the connection (the run has ended?)');
    my $line = <$sock>;
    _fail('the robot closed the connection (the run has ended?)') unless defined $line;
    my $reply = $json->decode($line);
    if (my $error = $reply->{error}) {
        _fail($error->{message} // 'robot error', code => $error->{code}, data => $error->{data});
    }
    return $reply->{result};
}

# Numbers go out as JSON numbers even when they came in as text (from @ARGV, a file, a regex).
sub _number {
    my ($name, $value) = @_;
    _fail("$name must be a number, not " . ($value // 'undef')) unless looks_like_number($value);
    return 0 + $value;
}

sub _fail {
    my ($message, %args) = @_;
    die Robot::Error->new(message => $message, where => Carp::shortmess(''), %args);
}

sub drive {
    my ($self, $linear, $angular) = @_;
    return $self->call('drive', _number(linear => $linear), _number(angular => $angular // 0));
}

sub stop         { $_[0]->call('stop') }
sub sensors      { $_[0]->call('sensors') }    # heading (deg), range (m), position {x, y, theta}, ...
sub sensor       { $_[0]->call('sensor', $_[1]) }
sub capabilities { $_[0]->call('capabilities') }
sub show         { $_[0]->call('show', $_[1], $_[2]) }    # a number, a text or an SVG text
sub publish      { $_[0]->call('publish', $_[1], $_[2]) } # returns how many subscribers it reached
sub subscribe    { $_[0]->call('subscribe', $_[1]) }
sub memory_set   { $_[0]->call('memory_set', $_[1], $_[2]) }
sub memory_get   { $_[0]->call('memory_get', $_[1]) }

# The next value published on $topic since subscribing; undef after $timeout seconds
# (no timeout: wait for ever).
sub receive {
    my ($self, $topic, $timeout) = @_;
    return $self->call('receive', $topic, defined $timeout ? _number(timeout => $timeout) : undef);
}

sub say          { $_[0]->call('say', $_[1]) }    # { spoken => 1 or 0, seconds, or reason }
sub snapshot     { $_[0]->call('snapshot') }
sub scan_barcode { $_[0]->call('scan_barcode') }

# Speech recognised: $seconds from the microphone (default 5), or the WAV file $wav in the
# program's folder; $words (an array ref) listens for those only. Returns { text, words }.
sub listen {
    my ($self, $seconds, $wav, $words) = @_;
    return $self->call('listen', defined $seconds ? _number(seconds => $seconds) : undef,
        $wav, $words);
}

sub close {
    my ($self) = @_;
    CORE::close(delete $self->{sock}) if $self->{sock};
    return;
}

1;
