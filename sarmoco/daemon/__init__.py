"""The process: command line, configuration, pipeline wiring, buffers, recorder, status.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array_pipeline",
    "array_report",
    "camera",
    "config",
    "echoring",
    "focuser",
    "georeference",
    "logging_setup",
    "pipeline",
    "recorder",
    "report",
    "resources",
    "runner",
    "schema",
    "status",
    "store",
    "tables",
    "threadcpu",
    "verify",
]
