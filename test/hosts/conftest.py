"""The two hosts of the ``hosts`` tests: two network namespaces joined by a veth pair
(benchmarks/netns.py; root and the ``ip`` command needed, skipped with the reason otherwise)."""

from __future__ import annotations

import pytest

from benchmarks.netns import NotRunnable
from benchmarks.netns import two_hosts as _two_hosts


@pytest.fixture
def two_hosts():
    """A :class:`benchmarks.netns.Hosts` (namespaces, link addresses, veth ends), removed
    afterwards."""
    try:
        with _two_hosts() as h:
            yield h
    except NotRunnable as exc:
        pytest.skip(str(exc))
