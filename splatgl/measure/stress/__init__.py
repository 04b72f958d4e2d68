"""Numerical stress tests: scenes built to break renderers, and the report that runs them.

:mod:`.cases` builds each case (scene, camera, settings, the error bound per renderer and why);
:mod:`.run` renders every case with the quad path, the tile renderer and the NumPy reference in
float32, checks finiteness and the error against the float64 reference, and formats the table;
:mod:`.fixes` lists the guards added to the renderers and what failed before each.
"""

from .cases import CASES, StressCase, case_by_name
from .fixes import FIXES, Fix
from .run import CaseResult, RendererResult, format_report, run_case, run_cases

__all__ = ["CASES", "StressCase", "case_by_name", "FIXES", "Fix", "CaseResult",
           "RendererResult", "format_report", "run_case", "run_cases"]
