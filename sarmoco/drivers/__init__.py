"""Links: bytes in, typed and timestamped samples out (MAVLink, SBG, CAN, VITA 49)."""
