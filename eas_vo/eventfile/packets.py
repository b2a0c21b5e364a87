"""The packed event encodings of event-camera drivers (`event_camera_msgs/EventPacket`'s
`encoding`, Prophesee's `.raw` files): what each decoder returns, and the decoder of each name.

A decoder is made once per stream and fed its packets in order (some encodings carry state from
one packet to the next: EVT 3.0's time high and its 24-bit roll-over).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Decoded:
    """The events and external triggers of one packet, on the sensor's clock.

    Attributes:
        t_ns: (N,) int64 event times [ns] on the sensor's clock (the encoding's unit scaled to ns).
        x, y: (N,) uint16 pixel coordinates [px].
        p: (N,) uint8 polarity, 1 = ON (brighter), 0 = OFF.
        trigger_t_ns: (M,) int64 times [ns] of external trigger edges.
        trigger_edge: (M,) uint8, 1 = rising, 0 = falling.
        trigger_id: (M,) uint8, the trigger channel.
    """

    t_ns: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    trigger_t_ns: np.ndarray
    trigger_edge: np.ndarray
    trigger_id: np.ndarray


class PacketDecoder:
    """Decodes one stream's packets, in order.

    `__init__(width, height)`: the sensor size [px] (events outside it are the decoder's to
    refuse: ValueError naming the word). `decode(data, time_base_ns)`: one packet's bytes
    (uint8 array) and its message's `time_base` [ns] (0 where the driver sets none) -> Decoded;
    ValueError for bytes that are not of the encoding (naming the offset).
    """

    #: The encoding's name, as event_camera_msgs spells it.
    encoding: str = ""
    #: Events dropped so far: outside the sensor, and before the stream's first full time.
    outside: int = 0
    skipped: int = 0
    #: Whether the sensor's clock was set to the host's when the driver started (libcaer), so
    #: that its times are on the bag's clock already; else (evt3) they count from the sensor's start.
    host_clock: bool = False

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height

    def decode(self, data: np.ndarray, time_base_ns: int) -> Decoded:
        raise NotImplementedError


#: Each encoding's decoder class, as "module:Class" (imported when first met).
DECODERS = {
    "evt3": "eas_vo.eventfile.prophesee:Evt3Decoder",
    "libcaer": "eas_vo.eventfile.libcaer:LibcaerDecoder",
    "libcaer_cmp": "eas_vo.eventfile.libcaer:LibcaerCmpDecoder",
}


def decoder_class(encoding: str) -> type[PacketDecoder] | None:
    """The decoder of a packed encoding's name, or None for one not read."""
    import importlib

    if encoding not in DECODERS:
        return None
    module, name = DECODERS[encoding].split(":")
    return getattr(importlib.import_module(module), name)
