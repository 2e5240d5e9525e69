"""Recovery of a known motion error injected into the GOTCHA data.

The command line of :mod:`tests.workloads.gotcha_autofocus` (the workload, shared with the tests)::

    .venv/bin/python -m bench.gotcha_autofocus
"""

from __future__ import annotations

import numpy as np

from sarmoco.drivers.gotcha import read_gotcha
from tests.workloads.gotcha_autofocus import FILES, OUT, plot, recover, rms


def main() -> None:
    r = recover(read_gotcha(FILES))
    print(
        f"injected: {np.ptp(r.injected_m) / r.cell_m:.2f} cells peak-to-peak, "
        f"{rms(4 * np.pi * r.injected_m / r.wavelength_m):.1f} rad rms at the carrier"
    )
    print(
        f"entropy: provided {r.entropy_provided:.4f}, corrupted {r.entropy_corrupted:.4f}, "
        f"recovered {r.entropy_recovered:.4f} (bar {1.01 * r.entropy_provided:.4f})"
    )
    print(
        f"envelope error {rms(r.envelope_error_m) * 1e3:.2f} mm rms "
        f"({rms(r.envelope_error_m) / r.cell_m:.3f} cell); "
        f"phase error {rms(r.phase_error_rad):.3f} rad rms; "
        f"phase passes {[round(x, 3) for x in r.result.rms_updates_rad]}"
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    plot(r, OUT)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
