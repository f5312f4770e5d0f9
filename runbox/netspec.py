"""What a robot's settings may say about its runs' network, checked."""

import ipaddress

# Never reachable from a `full` run unless a robot's `allow_networks` names one: the private
# and link-local ranges (a LAN's servers, a cloud's metadata address).
PRIVATE_RANGES = (
    "0.0.0.0/8", "10.0.0.0/8", "100.64.0.0/10", "127.0.0.0/8", "169.254.0.0/16",
    "172.16.0.0/12", "192.0.0.0/24", "192.168.0.0/16", "198.18.0.0/15", "224.0.0.0/4",
    "240.0.0.0/4",
)  # fmt: skip
PROTOCOLS = ("tcp", "udp")


def parse_ports(values) -> tuple[str, ...]:
    """["tcp:9090", "udp:5600"]: loopback services of the host relayed into each run."""
    if isinstance(values, str):
        values = [v for v in values.replace(",", " ").split() if v]
    ports = []
    for value in values or ():
        proto, _, port = str(value).partition(":")
        if proto not in PROTOCOLS or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"loopback_ports: {value!r} is not tcp:PORT or udp:PORT")
        ports.append(f"{proto}:{int(port)}")
    return tuple(dict.fromkeys(ports))


def parse_networks(values) -> tuple[str, ...]:
    """["192.168.10.0/24"]: private ranges a `full` run may reach all the same."""
    if isinstance(values, str):
        values = [v for v in values.replace(",", " ").split() if v]
    networks = []
    for value in values or ():
        try:
            network = ipaddress.ip_network(str(value), strict=False)
        except ValueError:
            raise ValueError(f"allow_networks: {value!r} is not an address range") from None
        if network.version != 4:
            raise ValueError(f"allow_networks: {value!r}: runs have IPv4 only")
        networks.append(str(network))
    return tuple(networks)


def host_addresses(fib_trie: str = "/proc/net/fib_trie") -> list[str]:
    """This machine's own IPv4 addresses (a server listening on all of them must not be
    reachable through a public one either)."""
    try:
        lines = open(fib_trie).read().splitlines()
    except OSError:
        return []
    found = {
        previous.split()[-1]
        for previous, line in zip(lines, lines[1:], strict=False)
        if line.strip() == "/32 host LOCAL"
    }
    return sorted(found)


# Shut whatever a robot allows: 0.0.0.0 and the loopback are this machine (so are its own
# addresses, found at the box's start), where PostgreSQL, Redis and the web server listen.
ALWAYS_SHUT = ("0.0.0.0/8", "127.0.0.0/8")


def blocked_ranges(allowed: tuple[str, ...], own: list[str] = ()) -> list[str]:
    """The private ranges minus what is allowed, then this machine's loopback and own
    addresses whatever is allowed, as routes that refuse (a range is split around an allowed
    part; an allowed LAN the host is on stays open but for the host)."""
    allowed_nets = [ipaddress.ip_network(a) for a in allowed]
    blocked: list[ipaddress.IPv4Network] = []
    for text in PRIVATE_RANGES:
        parts = [ipaddress.ip_network(text)]
        for keep in allowed_nets:
            parts = [
                piece
                for part in parts
                for piece in (
                    part.address_exclude(keep) if keep.subnet_of(part)
                    else ([] if part.subnet_of(keep) else [part])
                )
            ]  # fmt: skip
        blocked += parts
    blocked += [ipaddress.ip_network(text) for text in ALWAYS_SHUT]
    blocked += [ipaddress.ip_network(f"{address}/32") for address in own]
    return list(dict.fromkeys(str(net) for net in blocked))
