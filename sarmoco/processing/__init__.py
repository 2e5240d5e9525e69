"""Pure numpy/scipy signal processing: no I/O, no threads, no imports of daemon, drivers or sim."""
