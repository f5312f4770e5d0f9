"""What a robot's settings may open of a `full` run's network, and what stays shut whatever
they say: this machine's own addresses and its loopback (a server listening on all addresses,
PostgreSQL or the web server, answers on each of them)."""

import ipaddress

import pytest

from runbox.netspec import blocked_ranges, parse_networks, parse_ports

OWN = ["127.0.0.1", "192.168.1.20"]


def refused(allowed, own=OWN) -> list:
    return [ipaddress.ip_network(n) for n in blocked_ranges(tuple(allowed), own)]


def is_refused(address: str, allowed, own=OWN) -> bool:
    return any(ipaddress.ip_address(address) in net for net in refused(allowed, own))


def test_nothing_allowed_refuses_the_private_ranges_and_the_hosts_own_addresses():
    for address in ("10.1.2.3", "172.16.0.1", "192.168.7.7", "169.254.169.254", "127.0.0.1"):
        assert is_refused(address, [])
    assert is_refused("203.0.113.9", [], own=["203.0.113.9"])  # a public address of its own
    assert not is_refused("198.51.100.7", [])  # the internet


def test_an_allowed_lan_is_open_but_not_the_host_on_it():
    """A teacher opens the lab's LAN to reach its robots' cameras: the machine robotide runs on
    is on that LAN too, and stays out of reach."""
    lan = ["192.168.1.0/24"]
    assert not is_refused("192.168.1.30", lan)
    assert is_refused("192.168.1.20", lan)
    assert is_refused("192.168.2.1", lan)  # the rest of the range stays shut


def test_allowing_everything_still_leaves_the_host_shut():
    everything = ["0.0.0.0/0"]
    for address in ("127.0.0.1", "127.8.9.10", "192.168.1.20", "0.0.0.0"):
        assert is_refused(address, everything), address
    assert not is_refused("10.9.9.9", everything)


def test_a_part_of_a_range_splits_it_around_the_allowed_part():
    nets = refused(["10.1.0.0/16"])
    assert ipaddress.ip_network("10.0.0.0/8") not in nets
    assert is_refused("10.0.0.1", ["10.1.0.0/16"]) and is_refused("10.2.0.1", ["10.1.0.0/16"])
    assert not is_refused("10.1.200.1", ["10.1.0.0/16"])


@pytest.mark.parametrize("bad", ["lab", "10.0.0.0/33", "fd00::/8"])
def test_a_bad_range_is_refused_with_its_setting_named(bad):
    with pytest.raises(ValueError, match="allow_networks"):
        parse_networks([bad])


def test_ranges_and_ports_come_as_lists_or_text():
    assert parse_networks("10.1.2.3/16, 192.168.5.0/24") == ("10.1.0.0/16", "192.168.5.0/24")
    assert parse_ports("tcp:9090 udp:5600 tcp:9090") == ("tcp:9090", "udp:5600")
    with pytest.raises(ValueError, match="loopback_ports"):
        parse_ports(["tcp:0"])
