"""Links: bytes in, typed and timestamped samples out (MAVLink, SBG, CAN, VITA 49).

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "attitude",
    "can_source",
    "clock",
    "gotcha",
    "mavlink",
    "radar",
    "samples",
    "sbg",
    "sbg_can",
    "sbg_codec",
    "slcan_status",
    "source",
    "vita49",
]
