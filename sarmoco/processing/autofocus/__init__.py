"""Echo-based autofocus: sliding-subaperture two-step method (docs/methods.md §3) and PGA.

Public entry points: :class:`SlidingSubapertureAutofocus` (streaming),
:func:`autofocus_offline` (whole aperture), :func:`pga` (refinement), and the records in
:mod:`.report`.
"""

from sarmoco.processing.autofocus.corrections import Corrections
from sarmoco.processing.autofocus.offline import autofocus_offline
from sarmoco.processing.autofocus.report import AutofocusReport, LineRates, SubapertureReport
from sarmoco.processing.autofocus.settings import AutofocusConfig, AutofocusGeometry
from sarmoco.processing.autofocus.streaming import SlidingSubapertureAutofocus

__all__ = [
    "AutofocusConfig",
    "AutofocusGeometry",
    "AutofocusReport",
    "Corrections",
    "LineRates",
    "SlidingSubapertureAutofocus",
    "SubapertureReport",
    "autofocus_offline",
    "report",
    "settings",
    "splice",
]
