"""Applications above the daemon, the products and the simulator: the command line, the
demo, ``sarmoco sim``, the exports, the report against a simulated run's truth.

The layer joins ``sarmoco.daemon`` (the process), ``sarmoco.products`` (what is made from a
store) and ``sarmoco.sim`` (simulated hardware); none of them imports it, and the daemon
never imports the simulator or the products.


``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "cli",
]
