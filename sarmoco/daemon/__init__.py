"""The process that flies: configuration, links, buffers, alignment, pipeline, status.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array_pipeline",
    "camera",
    "config",
    "echoring",
    "focuser",
    "livefeed",
    "logging_setup",
    "navbuffer",
    "pipeline",
    "resources",
    "runner",
    "status",
    "threadcpu",
]
