"""The address a Foxglove WebSocket server binds: ``[HOST:]PORT`` of ``--foxglove`` (light:
no websockets import, so ``fence-sorter run`` checks it before anything starts)."""

from __future__ import annotations

import ipaddress
import socket

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


def check_free(address: tuple[str, int], option: str = "--foxglove") -> None:
    """AddressError (naming ``option`` and HOST:PORT) unless a server can listen at ``address``
    now, e.g. the port is in use; the socket is closed again at once."""
    host, port = address
    try:
        family, kind, proto, _, sockaddr = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds
            sock.bind(sockaddr)
    except OSError as exc:
        raise AddressError(
            f"{option} {host}:{port}: cannot listen there: {exc.strerror or exc}"
        ) from None
