"""The address a Foxglove WebSocket server binds: ``[HOST:]PORT`` of ``--foxglove`` (light:
no websockets import, so ``fence-sorter run`` checks it before anything starts)."""

from __future__ import annotations

import ipaddress

#: the host the server binds to unless told otherwise: this machine only
DEFAULT_HOST = "127.0.0.1"


class AddressError(ValueError):
    """A bad ``[HOST:]PORT`` (one line naming the option and the allowed values)."""


def parse_address(text: str, option: str = "--foxglove") -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); HOST an IP address or ``localhost`` (default
    127.0.0.1), PORT in 1-65535. AddressError names ``option`` and the allowed values."""
    host, sep, port_text = str(text).rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]")
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 1 <= port <= 65535:
        raise AddressError(f"{option} must be [HOST:]PORT with PORT in 1-65535, got {text!r}")
    if host != "localhost":
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise AddressError(
                f"{option} HOST must be an IP address or localhost, got {host!r}"
            ) from None
    return host, port
