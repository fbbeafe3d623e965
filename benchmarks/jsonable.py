"""One helper the benchmark scripts share (``benchmarks/`` is not a package: a script imports it
after putting its own folder on ``sys.path``, which also works when a test loads the script from
its file)."""

from __future__ import annotations

import math


def jsonable(value):
    """``value`` with every non-finite float (NaN, ±inf) replaced by None, through dicts, lists
    and tuples (tuples become lists), for ``json.dumps`` (strict JSON has no NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value
