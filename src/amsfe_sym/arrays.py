"""The numpy array types of the toolkit's signatures, defined once.

Shapes and units are the docstrings' business: ``FloatArray`` is any float64 array,
``IntArray`` any int64 array.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["FloatArray", "IntArray"]

#: A float64 array of any shape.
FloatArray = NDArray[np.float64]
#: An int64 array of any shape (stamps [ns], indices, counts).
IntArray = NDArray[np.int64]
