"""Applications above the daemon and the simulator: the command line, the demo, ``sarmoco sim``.

The layer joins ``sarmoco.daemon`` (the process) and ``sarmoco.sim`` (simulated
hardware); neither of them imports it, and the daemon never imports the simulator.


``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "cli",
]
