"""Plain-Python conversion of results for `json.dumps`: never NaN or Infinity."""

import math
from typing import Any


def _finite_or_none(v, path, nulls):
    if isinstance(v, list):
        return [_finite_or_none(x, f"{path}[{i}]", nulls) for i, x in enumerate(v)]
    if isinstance(v, float) and not math.isfinite(v):
        nulls.append(path)
        return None
    return v


def to_jsonable(obj, nulls=None, path="") -> Any:  # the JSON value of `obj`
    """numpy/JAX arrays and scalars to plain Python for `json.dumps`.

    Non-finite numbers (NaN, inf) become `None` (JSON `null`, since strict JSON has no
    NaN); their paths (e.g. `"measured_steps_100x"`, `"largest[3][1]"`) are appended to
    `nulls` when given, so that the caller can say why.
    """
    import numpy as np

    nulls = [] if nulls is None else nulls
    if isinstance(obj, dict):
        return {k: to_jsonable(v, nulls, f"{path}.{k}" if path else str(k)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, nulls, f"{path}[{i}]") for i, v in enumerate(obj)]
    if hasattr(obj, "shape") or isinstance(obj, (np.generic,)):
        arr = np.asarray(obj)
        if np.iscomplexobj(arr):
            arr = np.stack([arr.real, arr.imag], axis=-1)
        return _finite_or_none(arr.tolist(), path, nulls)
    return _finite_or_none(obj, path, nulls)
