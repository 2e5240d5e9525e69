"""The process: command line, configuration, pipeline wiring, buffers, recorder, status."""
