"""The transports of a run whose nodes talk to other hosts: a Fast DDS profile per run.

A run on one host keeps to shared memory and loopback UDP (``config/fastdds_localhost.xml``).
With ``--interface ADDRESS --peers A[,B...]`` it talks to the other hosts of a line instead:
UDPv4 on the one interface that holds ADDRESS; discovery by unicast to ADDRESS and the peers'
addresses (Fast DDS's initial peers), so no multicast is needed on the link. The profile names
every participant's locators (UDP at ADDRESS), so Fast DDS announces no shared-memory locator:
its SHM transport is registered but carries nothing, and the participants of one host reach
each other by UDP at ADDRESS as well (delivered by the kernel on the host, never on the link).
Nothing passes between two hosts through /dev/shm, not even between two network namespaces of
one machine, which share it (docs/design/security.md). Every socket of the run is bound to
ADDRESS. The profile is written into the run's log directory and handed to every process of
the run, as the localhost one is.
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape


class TransportError(ValueError):
    """A bad --interface or --peers value (the message names the option)."""


@dataclass(frozen=True)
class HostsTransport:
    """UDPv4 on ``address`` (an address of this host), discovery through ``peers``."""

    address: str
    peers: tuple[str, ...]


def _ipv4(option: str, text: str) -> str:
    try:
        addr = ipaddress.IPv4Address(text.strip())
    except ValueError:
        raise TransportError(f"{option}: {text!r} is not an IPv4 address") from None
    if addr.is_unspecified or addr.is_multicast:
        raise TransportError(f"{option}: {text} must be one host's unicast address")
    return str(addr)


def hosts_transport(interface: str, peers: str) -> HostsTransport:
    """Check ``--interface`` (an IPv4 address held by an interface of this host) and
    ``--peers`` (comma-separated IPv4 addresses of the other hosts, at least one)."""
    address = _ipv4("--interface", interface)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((address, 0))
        except OSError:
            raise TransportError(
                f"--interface: {address} is not an address of this host's interfaces"
            ) from None
    names = [p for p in peers.split(",") if p.strip()]
    if not names:
        raise TransportError("--peers: give at least one IPv4 address of another host")
    found = tuple(_ipv4("--peers", p) for p in names)
    if address in found:
        raise TransportError(f"--peers: {address} is this host's --interface")
    return HostsTransport(address, found)


def _locator(address: str) -> str:
    return f"<locator><udpv4><address>{escape(address)}</address></udpv4></locator>"


def hosts_profile(t: HostsTransport) -> str:
    """The Fast DDS XML profile of ``t`` (the default participant profile)."""
    # this host's address too: its other participants (the run's nodes) are found the same way
    peers = "\n".join(f"            {_locator(p)}" for p in (t.address, *t.peers))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- fence_sorter run across hosts (fence_sorter/runner/transport.py): UDPv4 on {t.address}
     only, within this host as well (the locators are UDP ones: the SHM transport carries
     nothing), discovery by unicast to the peers. -->
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>fence_sorter_shm</transport_id>
        <type>SHM</type>
      </transport_descriptor>
      <transport_descriptor>
        <transport_id>fence_sorter_udp_link</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList>
          <address>{escape(t.address)}</address>
        </interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="fence_sorter_hosts" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>fence_sorter_shm</transport_id>
          <transport_id>fence_sorter_udp_link</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <metatrafficUnicastLocatorList>
            {_locator(t.address)}
          </metatrafficUnicastLocatorList>
          <initialPeersList>
{peers}
          </initialPeersList>
          <discovery_config>
            <initialAnnouncements>
              <count>30</count>
              <period>
                <nanosec>100000000</nanosec>
              </period>
            </initialAnnouncements>
          </discovery_config>
        </builtin>
        <defaultUnicastLocatorList>
          {_locator(t.address)}
        </defaultUnicastLocatorList>
      </rtps>
    </participant>
  </profiles>
</dds>
"""


def write_profile(t: HostsTransport, directory: Path) -> Path:
    """Write the profile of ``t`` into ``directory``; its path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "fastdds_hosts.xml"
    path.write_text(hosts_profile(t))
    return path
