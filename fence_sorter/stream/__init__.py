"""Parcel streams for the scanner (ROS-free): random from distributions, or CSV manifests."""

from fence_sorter.stream.model import (
    DEFAULT_STREAM,
    Distribution,
    ParcelSpec,
    StreamConfig,
    StreamError,
    generate,
    load_stream,
    read_manifest,
    resolve_stream,
)

__all__ = [
    "DEFAULT_STREAM",
    "Distribution",
    "ParcelSpec",
    "StreamConfig",
    "StreamError",
    "generate",
    "load_stream",
    "read_manifest",
    "resolve_stream",
]
