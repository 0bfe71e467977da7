"""Plain-Python conversion of results for `json.dumps`."""

import math


def to_jsonable(obj):
    """numpy/JAX arrays and scalars to plain Python for `json.dumps`."""
    import numpy as np

    if isinstance(obj, dict):
        return {k: to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if hasattr(obj, "shape") or isinstance(obj, (np.generic,)):
        arr = np.asarray(obj)
        if np.iscomplexobj(arr):
            arr = np.stack([arr.real, arr.imag], axis=-1)
        return arr.tolist()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
