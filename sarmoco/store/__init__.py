"""The run store: the zarr layout one run is recorded in, its writer and its reader.

The flying daemon writes a store (:mod:`~sarmoco.store.recorder`) and the ground reads
it (:mod:`~sarmoco.store.reader`, :mod:`~sarmoco.store.verify`); both follow the one
declaration of the layout in :mod:`~sarmoco.store.schema`, and the per-pulse flags recorded
with it are :mod:`~sarmoco.store.flags`. The store imports processing and drivers (the types
it records), never the daemon, the products, the simulator or the applications.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "flags",
    "reader",
    "recorder",
    "schema",
    "verify",
]
