"""The process: configuration, links, buffers, alignment, focusing, status and live page,
the live runner and the replay; it records through :mod:`sarmoco.store`.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array_pipeline",
    "camera",
    "config",
    "focuser",
    "livelevel",
    "logging_setup",
    "pipeline",
    "resources",
    "runner",
    "status",
    "tables",
    "threadcpu",
]
