# Tcl client for the robotide Robot API (Tcl 8.6 and tcllib's json; huddle for typed values).
#
#   package require robot
#   robot::drive 0.2 0                  ;# linear m/s, angular rad/s (clamped to the limits)
#   puts [dict get [robot::sensors] heading]
#   robot::show heading 42              ;# appears live on the robot's page
#   robot::stop
#   robot::say "I'm home"               ;# spoken, and shown on the robot's page
#   foreach code [robot::scan_barcode] { puts [dict get $code text] }  ;# the codes in view
#   dict get [robot::listen 3 "" {move stop}] text   ;# move, or "" when none was heard
#
# The first command connects with $ROBOT_API_TCP (Tcl has no Unix sockets; else $ROBOT_API if it
# is host:port) and $ROBOT_TOKEN; robot::connect ?address? ?token? does it explicitly. Where no
# TCP reaches the API (network "none"), `robot pipe` relays to its Unix socket.
#
# Values: a value that is a JSON number (42, -0.5, 1e3) is sent as a number, any other as a
# string; names, topics and keys always as strings. For true, false, null, lists and objects
# pass a tcllib huddle: [huddle true], [huddle null], [huddle list 1 2],
# [huddle create x [huddle number 1]]. Results are decoded with tcllib's json::json2dict:
# objects are dicts, arrays lists, true/false/null inside them the words true, false and null;
# a null result is the empty string.
#
# An error the robot reports is a Tcl error with its message and -errorcode {ROBOT code},
# e.g. {ROBOT -32000} for a sensor the robot lacks.

package require Tcl 8.6
package require json

namespace eval robot {
    variable sock ""
    variable next_id 0
    variable here [file dirname [file normalize [info script]]]
    namespace export drive stop sensors sensor capabilities show publish subscribe receive \
        memory_set memory_get say snapshot scan_barcode listen call connect close
}

namespace eval robot::json {
    # " and \ and the control characters, as JSON escapes
    variable escapes [list \\ \\\\ \" \\\" \b \\b \f \\f \n \\n \r \\r \t \\t]
    for {set c 0} {$c < 0x20} {incr c} {
        if {[::string first [format %c $c] "\b\f\n\r\t"] < 0} {
            lappend escapes [format %c $c] [format \\u%04x $c]
        }
    }
    unset c
    variable number {^-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?$}
}

# A JSON string literal for any text.
proc robot::json::string {text} {
    variable escapes
    return "\"[::string map $escapes $text]\""
}

# A JSON number for a Tcl number (1, 0.5, .5, 1e3, 0x10); other values go as text, for the
# robot to refuse with a clear message.
proc robot::json::number {value} {
    variable number
    if {[regexp $number $value]} {
        return $value
    }
    if {[::string is double -strict $value]} {
        set value [expr {double($value)}]
        if {![regexp $number $value]} {
            return -code error "not a finite number: $value"
        }
        return $value
    }
    return [string $value]
}

# JSON for a value: a huddle by its types, a JSON number as a number, anything else as text.
proc robot::json::encode {value} {
    variable number
    if {[regexp $number $value]} {
        return $value
    }
    if {[::string match {HUDDLE *} $value] && [llength $value] == 2} {
        package require huddle
        if {[huddle isHuddle $value]} {
            return [huddle_json $value]
        }
    }
    return [string $value]
}

proc robot::json::huddle_json {node} {
    switch -- [huddle type $node] {
        string  { return [string [huddle get_stripped $node]] }
        number  { return [number [huddle get_stripped $node]] }
        boolean { return [expr {[huddle get_stripped $node] ? "true" : "false"}] }
        null    { return null }
        list {
            set items {}
            for {set i 0} {$i < [huddle llength $node]} {incr i} {
                lappend items [huddle_json [huddle get $node $i]]
            }
            return "\[[join $items ,]\]"
        }
        dict {
            set members {}
            foreach key [huddle keys $node] {
                lappend members "[string $key]:[huddle_json [huddle get $node $key]]"
            }
            return "{[join $members ,]}"
        }
        default { return -code error "cannot encode a huddle of type [huddle type $node]" }
    }
}

# Connects and authenticates; address and token default to the environment.
proc robot::connect {{address ""} {token ""}} {
    variable sock
    global env
    if {$address eq ""} {
        if {[info exists env(ROBOT_API_TCP)] && $env(ROBOT_API_TCP) ne ""} {
            set address $env(ROBOT_API_TCP)
        } elseif {[info exists env(ROBOT_API)]} {
            set address $env(ROBOT_API)
        }
    }
    if {$token eq "" && [info exists env(ROBOT_TOKEN)]} {
        set token $env(ROBOT_TOKEN)
    }
    if {$address eq "" || $token eq ""} {
        return -code error -errorcode {ROBOT NOTSET} \
            "ROBOT_API_TCP and ROBOT_TOKEN are not set: run this program from robotide"
    }
    close
    if {[::string match unix:* $address]} {
        # Tcl has no Unix sockets: the robot command relays for it (as under network "none").
        set sock [Relay $address]
        Authenticate $token
        return
    }
    if {![regexp {^(.*):([0-9]+)$} $address -> host port]} {
        return -code error -errorcode {ROBOT ADDRESS} \
            "bad Robot API address $address: expected host:port"
    }
    regexp {^\[(.*)\]$} $host -> host
    if {$host eq ""} {
        set host 127.0.0.1
    }
    if {[catch {socket $host $port} channel]} {
        if {[info exists env(ROBOT_API)] && [::string match unix:* $env(ROBOT_API)]} {
            set sock [Relay $env(ROBOT_API)]  ;# no network here: through the Unix socket
            Authenticate $token
            return
        }
        return -code error -errorcode {ROBOT CONNECT} \
            "cannot reach the Robot API at $address: $channel"
    }
    fconfigure $channel -translation lf -encoding utf-8 -buffering full -blocking 1
    set sock $channel
    Authenticate $token
    return
}

proc robot::Authenticate {token} {
    if {[catch {Request auth [list [json::string $token]]} message options]} {
        close
        return -options $options $message
    }
}

# A channel to the API through `robot pipe` (the shell client, beside this one).
proc robot::Relay {address} {
    variable here
    set tool [file join [file dirname $here] shell robot]
    set ::env(ROBOT_API) $address
    if {[catch {open |[list $tool pipe] r+} channel]} {
        return -code error -errorcode {ROBOT CONNECT} \
            "cannot reach the Robot API at $address through $tool: $channel"
    }
    fconfigure $channel -translation lf -encoding utf-8 -buffering full -blocking 1
    return $channel
}

proc robot::close {} {
    variable sock
    if {$sock ne ""} {
        catch {::close $sock}
        set sock ""
    }
    return
}

# Sends one request (params: a list of JSON texts) and returns the decoded result.
proc robot::Request {method params} {
    variable sock
    variable next_id
    if {$sock eq ""} {
        connect
    }
    incr next_id
    set request "{\"jsonrpc\":\"2.0\",\"id\":$next_id,\"method\":[json::string $method],"
    append request "\"params\":\[[join $params ,]\]}"
    if {[catch {puts $sock $request; flush $sock} message]} {
        close
        return -code error -errorcode {ROBOT CLOSED} "cannot send to the robot: $message"
    }
    if {[gets $sock line] < 0} {
        close
        return -code error -errorcode {ROBOT CLOSED} \
            "the robot closed the connection (the run has ended?)"
    }
    set reply [::json::json2dict $line]
    if {[dict exists $reply error]} {
        set error [dict get $reply error]
        set code [expr {[dict exists $error code] ? [dict get $error code] : -32000}]
        set message [expr {[dict exists $error message] ? [dict get $error message] : "robot error"}]
        return -code error -errorcode [list ROBOT $code] $message
    }
    if {![dict exists $reply result]} {
        return ""
    }
    set result [dict get $reply result]
    # json2dict gives null as the word null: a null result is the empty string, while the
    # text "null" is quoted on the line (and nothing else on a reply line is).
    if {$result eq "null" && [::string first {"null"} $line] < 0} {
        return ""
    }
    return $result
}

# Any Robot API method by name; each argument is encoded as robot::json::encode does.
proc robot::call {method args} {
    set params {}
    foreach value $args {
        lappend params [json::encode $value]
    }
    return [Request $method $params]
}

# Drives at linear m/s and angular rad/s; returns the applied speeds as a dict.
proc robot::drive {linear {angular 0}} {
    return [Request drive [list [json::number $linear] [json::number $angular]]]
}

proc robot::stop {} {
    return [Request stop {}]
}

# All readings as a dict: heading (deg), range (m), position {x y theta}, ...
proc robot::sensors {} {
    return [Request sensors {}]
}

proc robot::sensor {name} {
    return [Request sensor [list [json::string $name]]]
}

proc robot::capabilities {} {
    return [Request capabilities {}]
}

# Shows a number, a text or an SVG drawing (a text starting with <svg) by name.
proc robot::show {name value} {
    return [Request show [list [json::string $name] [json::encode $value]]]
}

# Sends value to the programs subscribed to topic; returns how many it reached.
proc robot::publish {topic value} {
    return [Request publish [list [json::string $topic] [json::encode $value]]]
}

# From now on this connection gets the messages published on topic.
proc robot::subscribe {topic} {
    return [Request subscribe [list [json::string $topic]]]
}

# The next value published on topic; "" after timeout seconds ("" : wait for ever).
proc robot::receive {topic {timeout ""}} {
    set wait [expr {$timeout eq "" ? "null" : [json::number $timeout]}]
    return [Request receive [list [json::string $topic] $wait]]
}

# Stores value under key in the memory the robot's programs share.
proc robot::memory_set {key value} {
    return [Request memory_set [list [json::string $key] [json::encode $value]]]
}

# The value stored under key, or "".
proc robot::memory_get {key} {
    return [Request memory_get [list [json::string $key]]]
}

# Speaks text (shown on the robot's page too); returns a dict: spoken (true or false), and
# seconds, or reason when it was not spoken.
proc robot::say {text} {
    return [Request say [list [json::string $text]]]
}

# The camera's frame now: a dict of jpeg (the JPEG in base64), width and height.
proc robot::snapshot {} {
    return [Request snapshot {}]
}

# The barcodes and QR codes in view: a list of dicts of text, format and position.
proc robot::scan_barcode {} {
    return [Request scan_barcode {}]
}

# Recognises speech: seconds from the microphone, or the WAV file wav in the program's folder
# ("" : none); words, a list, listens for those only. Returns a dict of text and words.
proc robot::listen {{seconds 5} {wav ""} {words ""}} {
    set params [list [json::number $seconds]]
    lappend params [expr {$wav eq "" ? "null" : [json::string $wav]}]
    if {[llength $words] == 0} {
        lappend params null
    } else {
        set items {}
        foreach word $words {
            lappend items [json::string $word]
        }
        lappend params "\[[join $items ,]\]"
    }
    return [Request listen $params]
}

package provide robot 1.0
