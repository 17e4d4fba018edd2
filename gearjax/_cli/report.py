"""What every command prints: exit codes, JSON on stdout, one line on stderr."""

from __future__ import annotations

import json
import math
import sys
from fractions import Fraction

from .._errors import one_line

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT, EXIT_NOT_CONVERGED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def to_stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def brief(e, limit: int = 300) -> str:
    text = one_line(" ".join(str(e).split())) or type(e).__name__
    return text if len(text) <= limit else text[:limit - 3] + "..."


def emit(obj) -> int:
    print(json.dumps(_json_safe(obj), allow_nan=False, indent=1))
    return EXIT_OK


def _json_safe(obj):
    """Replace NaN/inf with null (interface.md: JSON never holds NaN or Infinity)."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, Fraction):
        return float(obj)
    if hasattr(obj, "item") and not isinstance(obj, str):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
