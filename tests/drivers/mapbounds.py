"""Observe the error bound a MAVLink source's clock model states as it maps each sample."""

from __future__ import annotations

from sarmoco.drivers.mavlink import MavlinkSource


def observe_map_bounds(src: MavlinkSource) -> dict[int, int]:
    """Record the bound stated at the moment each boot time is mapped to GPS time.

    The bound read after a poll can be narrower than the one in force when a sample of
    that poll was mapped (a TIMESYNC reply later in the same poll tightens the fit), so a
    sample is judged against the bound of its own mapping.

    Parameters
    ----------
    src : MavlinkSource
        The source to observe; its clock model's ``map`` is wrapped, not replaced.

    Returns
    -------
    dict of int to int
        Boot time (ns) → the widest bound (ns) stated while mapping that boot time (a
        velocity and an attitude sample can share one boot time). Filled as samples map.
    """
    model = src.decoder.model
    map_boot = model.map
    bounds: dict[int, int] = {}

    def observed_map(device_ns: int) -> int:
        bounds[device_ns] = max(bounds.get(device_ns, 0), model.bound_ns)
        return map_boot(device_ns)

    model.map = observed_map  # type: ignore[method-assign]
    return bounds
